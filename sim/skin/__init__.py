"""The sensorized part and its skin: link meshes, module tiling, the part's taxel layout and
sensor mesh, the skin model (depth -> pressure -> 16-bit counts) and its readout from MuJoCo."""

# The default skin of datasets and commands: the forearm at 7.6 mm pad pitch (`forearm_x2` of
# `sim.skin.parts`, the lattice closest to the stated 8 mm). Measured on real CySkin prints at
# 1 mm: a single pad's mark covers 250-300 px; forearm_x2's 255 px, the 10.6 mm `forearm`'s
# 425 px (docs/stats.md). Here, not in `sim.skin.parts`, so that commands name it without
# loading trimesh.
DEFAULT_PART = "forearm_x2"
