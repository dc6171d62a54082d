"""The sensorized part and its skin: link meshes, module tiling, the part's taxel layout and
sensor mesh, the skin model (depth -> pressure -> 16-bit counts) and its readout from MuJoCo."""

from tactile.dataset.boxes import PAPER_PIXEL_MM

# The default skin of datasets and commands: the forearm at 5.9 mm pad pitch (`forearm_x3` of
# `sim.skin.parts`, 2,412 taxels), drawn on the paper's grid, `MAP_STEP_MM` of skin a pixel.
# Measured on real CySkin prints (docs/stats.md): a pixel of the paper's images covers 0.735 mm
# of skin (`PAPER_PIXEL_MM`: the hands' part boxes), and a single pad's mark 250-300 px, the mark
# of pads 8 px = 5.9 mm apart: forearm_x3's at 0.735 mm is 275 px (7.6 mm pads: 424 px, 5.3 mm:
# 235). Here, not in `sim.skin.parts`, so that commands name it without loading trimesh.
DEFAULT_PART = "forearm_x3"
MAP_STEP_MM = PAPER_PIXEL_MM
