"""The sensorized part and its skin: link meshes, module tiling, the part's taxel layout and
sensor mesh, the skin model (depth -> pressure -> 16-bit counts) and its readout from MuJoCo."""

from tactile.dataset.boxes import PAPER_PIXEL_MM

# The default skin of datasets and commands: the paper's skin region on the forearm
# (`forearm_paper` of `sim.skin.parts`: 1,320 taxels at 5.9 mm pad pitch on its top face and
# edges, 182 mm around x 260 mm along), drawn on the paper's grid, `MAP_STEP_MM` of skin a pixel.
# Measured on real CySkin prints (docs/stats.md): a pixel of the paper's images covers 0.735 mm
# of skin (`PAPER_PIXEL_MM`: the hands' part boxes), and a single pad's mark 250-300 px, the mark
# of pads 8 px = 5.9 mm apart (7.6 mm pads: 424 px, 5.3 mm: 235); the paper's 247 x 362 px map is
# then 182 x 266 mm, its columns along the link (forearm_paper's map: 246 x 349 px). Here, not in
# `sim.skin.parts`, so that commands name it without loading trimesh.
DEFAULT_PART = "forearm_paper"
MAP_STEP_MM = PAPER_PIXEL_MM
