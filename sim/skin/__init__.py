"""The sensorized part and its skin: link meshes, module tiling, the part's taxel layout and
sensor mesh, the skin model (depth -> pressure -> 16-bit counts) and its readout from MuJoCo."""
