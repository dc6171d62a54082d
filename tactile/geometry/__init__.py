"""The map's geometry: taxel layouts and their files, synthetic layouts, the surface mesh over
the taxels, its flattening (seams, packing) and the flat map's distortion."""
