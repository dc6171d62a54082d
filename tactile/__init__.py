"""Tactile maps and images from any taxel layout (numpy, scipy, scikit-image, libigl; no mujoco,
no torch).

    layout = TaxelLayout.load("left_forearm_V2.txt")    # or .npz / .csv
    tmap = TactileMap.build(layout, step_mm=1.0)          # triangulate, flatten, look-up table
    img = tmap.image(pressures_pa)                        # (H, W) uint8, the paper's image
"""

from tactile.errors import ConfigError, DataError, HandskinError, LayoutError, MapError
from tactile.geometry.flatten import Flattening, flatten
from tactile.geometry.layout import TaxelLayout
from tactile.geometry.surface import SurfaceMesh, triangulate
from tactile.images.faults import (
    blind_spots,
    dead_modules,
    gain_drift,
    nested_removal,
    stuck_at,
    zero_taxels,
)
from tactile.images.labels import (
    CLASS_NAMES,
    N_CLASSES,
    PALETTE,
    PartSummary,
    backproject,
    colorize,
    label_image,
    part_summary,
)
from tactile.images.resize import NET_SIZE, resize_image, resize_labels
from tactile.images.tactile_map import TactileMap

__all__ = [
    "CLASS_NAMES",
    "NET_SIZE",
    "N_CLASSES",
    "PALETTE",
    "ConfigError",
    "DataError",
    "Flattening",
    "HandskinError",
    "LayoutError",
    "MapError",
    "PartSummary",
    "SurfaceMesh",
    "TactileMap",
    "TaxelLayout",
    "backproject",
    "blind_spots",
    "colorize",
    "dead_modules",
    "flatten",
    "gain_drift",
    "label_image",
    "nested_removal",
    "part_summary",
    "resize_image",
    "resize_labels",
    "stuck_at",
    "triangulate",
    "zero_taxels",
]
