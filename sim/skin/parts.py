"""Sensorized robot parts: a link mesh, its `TaxelLayout` and the sensor mesh over the taxels.

Registry: `get_part(name)` for the built-in parts (`forearm`, `end_effector`, `plate`) and
`custom_part(mesh_path, region, tiling)` for any STL/OBJ link. Everything is in the link frame,
metres; the sensor mesh's vertices are the layout's taxels in layout order, its faces come from
`tactile.geometry.surface.triangulate` (the same triangulation the tactile map uses).
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from dataclasses import dataclass
from functools import lru_cache
from os import PathLike
from pathlib import Path

import numpy as np
import trimesh

from sim.skin import geometry, link_mesh
from sim.skin.tiling import PlaneRegion, Tiling, TubeRegion, module_lattice, tile
from tactile.errors import ConfigError
from tactile.geometry.layout import TaxelLayout
from tactile.geometry.surface import triangulate

TAXEL_PITCH_MM = 8.0  # stated pitch of the Schmitz et al. (2011) skin modules on the Baxter arm
# The default skins scale the whole module (pads and lattice alike, so modules still tile tightly
# and their seams are bridged) until 64 modules fill the paper's 247 x 362 mm map: 768 taxels at
# 8 mm pitch cover at most ~40 % of that box (see forearm_8mm), so the paper's taxel count and map
# size imply a coarser effective pitch. Scale 1.33 -> 10.6 mm pad pitch.
MODULE_SCALE = 1.33
SKIN_PITCH_MM = TAXEL_PITCH_MM * MODULE_SCALE

# The forearm (default): 64 modules on a tight 5 x 13 lattice with one slot left bare (a
# missing-module hole in the middle, as around a mounting point); the iCub pad pattern leaves
# small holes at module corners. Map 229 x 383 mm (paper 247 x 362 mm: -7 %, +6 %), 81 % of the
# box covered, one patch.
FOREARM_TILING = Tiling(
    5,
    13,
    col_pitch_mm=22.0 * MODULE_SCALE,
    row_pitch_mm=35.4 * MODULE_SCALE,
    pitch_mm=SKIN_PITCH_MM,
    keep=tuple("".join("." if (r, c) == (2, 6) else "X" for c in range(13)) for r in range(5)),
)

# forearm_8mm: the same 64 modules at the stated 8 mm pad pitch (768 taxels) on 64 of the 112
# slots of a tight 7 x 16 lattice (map about 247 x 362 mm, Albini & Cannata 2020). 64 modules
# cannot fill the box and only edge-sharing modules are bridged by the map's triangulation (~10 mm
# seams; the iCub pads leave ~20 mm gaps at corners), so the kept slots form one edge-connected
# lace whose
# holes are scattered instead of two 80 mm windows. Chosen by simulated annealing on swaps of
# kept/empty slots (8-10 modules per row, 15-17 per quarter of the columns) maximising, for random
# hand footprints (85 x 95 mm palm + fingers) and palms on the flat map, the 10th percentile of the
# covered fraction, with a penalty on the largest uncovered disc. Measured on the built map
# (3000 placements): hand p10 0.36 (three-band design: 0.23), palm p10 0.33 (0.16), palm min 0.17
# (0.06); largest uncovered disc radius 47 mm (42 mm), map 244 x 360 mm.
FOREARM_8MM_TILING = Tiling(
    7,
    16,
    col_pitch_mm=22.0,
    row_pitch_mm=35.4,
    pitch_mm=TAXEL_PITCH_MM,
    keep=(
        ".XX...XXXXX...X.",
        ".XXXXX....XXXXX.",
        ".XX..XXXX....XX.",
        ".XX..XX.XXX..XXX",
        "XXX..XX..XXXXX..",
        "..XX.XXX.X..XXXX",
        ".XXX...XXXX..X..",
    ),
)


def finer_forearm_tiling(n_rows: int) -> Tiling:
    """The forearm's lattice redrawn with smaller modules: `n_rows` rows instead of 5.

    Modules, pads and lattice shrink by 5 / n_rows (pad pitch 10.6 mm · 5 / n_rows), the column
    count whose pads span the forearm's width most closely, and the slots whose centroid lies in
    the forearm's bare module stay bare. Same box, taxel density (n_rows / 5)² times as high:
    parts `forearm_x2` (7 rows, 7.6 mm) and `forearm_x4` (10 rows, 5.3 mm) ask how much the
    taxel density limits what a network can read from a print (docs/findings.md, "A denser
    skin": at x2 SegNet's mIoU rises by 17 points, HandsNet's accuracy by nothing measurable);
    `forearm_x3` (9 rows, 5.9 mm, 3.2 times) is the default skin (`sim.skin.DEFAULT_PART`).
    """
    big = FOREARM_TILING
    if n_rows < 1:
        raise ConfigError(f"finer_forearm_tiling needs n_rows >= 1; got {n_rows}")
    f = big.n_rows / n_rows
    col, row = big.col_pitch_mm * f, big.row_pitch_mm * f
    pitch = big.pitch_mm * f
    width = np.ptp(big.flat()[0][:, 0])  # flat width of the forearm's pads, mm
    n_cols = min(
        range(1, 4 * big.n_cols * n_rows),
        key=lambda n: abs(np.ptp(Tiling(n_rows, n, col, row, pitch).flat()[0][:, 0]) - width),
    )
    centres, up = module_lattice(big.n_rows, big.n_cols, big.col_pitch_mm, big.row_pitch_mm)
    small, _ = module_lattice(n_rows, n_cols, col, row)
    bare = np.zeros(len(small), dtype=bool)
    for (x0, y0), is_up in zip(centres[~big.slots()], up[~big.slots()], strict=True):
        s = 1.0 if is_up else -1.0  # a down module is an up one turned by 180 degrees
        h = s * (small[:, 1] - y0)  # height above the centroid, towards the apex
        half_width = big.col_pitch_mm * (2 / 3 - h / big.row_pitch_mm)  # 0 at the apex
        bare |= (h >= -big.row_pitch_mm / 3) & (np.abs(small[:, 0] - x0) <= half_width)
    grid = bare.reshape(n_rows, n_cols)
    keep = tuple("".join("." if b else "X" for b in r) for r in grid[::-1])
    return Tiling(n_rows, n_cols, col, row, pitch, keep=keep)


FOREARM_REGION = TubeRegion((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0), center_m=0.16)

# The paper's skin region (the default skin): the top face of the forearm and its two edges, longer
# along the link than around it. Measured on the real prints (../shared/data/real_hands): the
# paper's 247 x 362 px map is 182 mm around x 266 mm along at 0.735 mm a pixel (its columns run
# along the link: index to little finger lie along the columns in 77 % of prints, thumb to
# fingers along the rows in 60 %, as in a grasp across the link), and the union of all 684
# prints' contact covers every row, so the skin ends where wrapping fingers run off it (54 % of
# prints reach the bottom row). forearm_x3's modules (5.9 mm pads) on 10 rows along x 11 columns
# around: pads span 254 mm along x 180 mm around, 1,320 taxels.
_X3 = finer_forearm_tiling(9)
PAPER_TILING = Tiling(10, 11, _X3.col_pitch_mm, _X3.row_pitch_mm, _X3.pitch_mm)
# Where the paper's people touched it: each of the five digits is boxed in 93-96 % of the real
# prints. Aimed anywhere on this skin, the MCP row shifted onto the edge the fingers cross, a
# digit showed in 56-69 % of hand prints (600 prints, seed 3): the fingers wrapped off the skin
# onto the bare side; aimed within 30 mm of the top face's middle, the palm shifted at most 25 mm
# (`sim.contactors.interactions.BAND_MAX_SHIFT_M`), in 66-84 % (400 prints; parts boxed, median:
# 4 -> 5, real 6 [5, 6]).
PAPER_AIM_BAND_MM = 30.0
# and at one place along the link: the real prints' centres lie at columns 94-119 of 362
# (quartiles; 10th-90th percentile 84-133, both folds alike), ours, aimed anywhere along the
# skin, at 82-219 of 349, and a digit near either end of the skin fell off it (in grasps 15-30 %
# of the thumb's, index's and middle finger's contacts lay off the skin, most past its ends).
# Aimed within 20 mm of the middle along the link (centres at 118-162, 40 mm: 111-171): digits
# boxed 61-84 -> 77-93 %, the print's span 148 -> 167 mm (real 162 / 161), its area 4,001 ->
# 5,199 mm2 (real 5,436 / 5,291), a finger's own mark 0.50 -> 0.60 (real 0.60); default set, seed 0.
PAPER_AIM_ALONG_MM = 20.0
PAPER_REGION = TubeRegion((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0), center_m=0.145)

# The gripper body: flat faces, 15 mm edge radius; two bands of 7 modules wrap its front and the
# two rounded front edges onto the sides (the back face and the top stay bare).
END_EFFECTOR_SIZE_M = (0.10, 0.08, 0.12)
END_EFFECTOR_EDGE_M = 0.015
END_EFFECTOR_TILING = Tiling(
    2, 7, col_pitch_mm=20.0 * MODULE_SCALE, row_pitch_mm=36.0 * MODULE_SCALE, pitch_mm=SKIN_PITCH_MM
)
END_EFFECTOR_REGION = TubeRegion((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0), center_m=0.0)

PLATE_SIZE_M = (0.20, 0.20, 0.01)
PLATE_TILING = Tiling(4, 8, col_pitch_mm=20.7, row_pitch_mm=35.9, pitch_mm=TAXEL_PITCH_MM)
PLATE_REGION = PlaneRegion((0.0, 0.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0))


@dataclass(frozen=True, eq=False)
class Part:
    """A sensorized link, all in the link frame (m).

    link : the link mesh (collision and visual). layout : the taxels (N). sensor_faces : (M, 3)
    int64 faces over the taxels, for the sensor mesh. flat_mm : (N, 2) the module lattice
    coordinates each taxel was placed from (mm; the tiling's design, not the tactile map).
    """

    name: str
    link: trimesh.Trimesh
    layout: TaxelLayout
    sensor_faces: np.ndarray
    flat_mm: np.ndarray
    description: str = ""
    aim_band_mm: float | None = None
    aim_along_mm: float | None = None

    @property
    def n_taxels(self) -> int:
        return self.layout.n_taxels


def make_part(
    name: str,
    link: trimesh.Trimesh,
    region: TubeRegion | PlaneRegion,
    tiling: Tiling,
    description: str = "",
    aim_band_mm: float | None = None,
    aim_along_mm: float | None = None,
) -> Part:
    """Tile `tiling` over `region` of `link` and triangulate the taxels into the sensor mesh."""
    layout, flat = tile(link, region, tiling, name=name)
    faces = np.asarray(triangulate(layout.positions_m, layout.normals).faces, dtype=np.int64)
    return Part(name, link, layout, faces, flat, description, aim_band_mm, aim_along_mm)


def forearm() -> Part:
    """Baxter-style upper forearm with 64 modules (768 taxels) on its upper part."""
    return make_part(
        "forearm",
        geometry.forearm_mesh(),
        FOREARM_REGION,
        FOREARM_TILING,
        "procedural Baxter-style upper forearm, 64 modules x 12 pads",
    )


def forearm_8mm() -> Part:
    """The forearm with its 64 modules at the stated 8 mm pad pitch: a lace covering ~40 %."""
    return make_part(
        "forearm_8mm",
        geometry.forearm_mesh(),
        FOREARM_REGION,
        FOREARM_8MM_TILING,
        "procedural Baxter-style upper forearm, 64 modules x 12 pads at 8 mm pitch (lace)",
    )


def finer_forearm(n_rows: int, name: str) -> Part:
    """The forearm with `finer_forearm_tiling(n_rows)`: same link and box, denser taxels."""
    tiling = finer_forearm_tiling(n_rows)
    return make_part(
        name,
        geometry.forearm_mesh(),
        FOREARM_REGION,
        tiling,
        f"procedural Baxter-style upper forearm, {int(tiling.slots().sum())} modules x 12 pads "
        f"at {tiling.pitch_mm:.1f} mm pitch (denser than the default)",
    )


def forearm_paper() -> Part:
    """The paper's skin region: 110 modules at 5.9 mm pad pitch over the forearm's top face and
    edges (`PAPER_TILING`), 182 mm around x 260 mm along: the default skin."""
    return make_part(
        "forearm_paper",
        geometry.forearm_mesh(),
        PAPER_REGION,
        PAPER_TILING,
        "procedural Baxter-style upper forearm, the paper's skin region: 110 modules x 12 pads "
        "at 5.9 mm pitch on its top face and edges",
        aim_band_mm=PAPER_AIM_BAND_MM,
        aim_along_mm=PAPER_AIM_ALONG_MM,
    )


def end_effector() -> Part:
    """Gripper body (rounded box) with 14 modules over its front and front edges."""
    mesh = geometry.rounded_box_mesh(END_EFFECTOR_SIZE_M, END_EFFECTOR_EDGE_M)
    return make_part(
        "end_effector",
        mesh,
        END_EFFECTOR_REGION,
        END_EFFECTOR_TILING,
        "rounded-box gripper body, 14 modules x 12 pads, partly covered",
    )


def plate() -> Part:
    """Flat 0.2 × 0.2 m plate with 32 modules on its top face (z = 0), for closed-form tests."""
    return make_part(
        "plate",
        geometry.plate_mesh(PLATE_SIZE_M),
        PLATE_REGION,
        PLATE_TILING,
        "flat test plate, 32 modules x 12 pads",
    )


PARTS: dict[str, Callable[[], Part]] = {
    "forearm_paper": forearm_paper,
    "forearm": forearm,
    "forearm_8mm": forearm_8mm,
    "forearm_x2": lambda: finer_forearm(7, "forearm_x2"),
    "forearm_x3": lambda: finer_forearm(9, "forearm_x3"),
    "forearm_x4": lambda: finer_forearm(10, "forearm_x4"),
    "end_effector": end_effector,
    "plate": plate,
}


@lru_cache(maxsize=8)
def get_part(name: str) -> Part:
    """The built-in part `name` (cached). KeyError lists the known parts."""
    if name not in PARTS:
        raise KeyError(f"unknown part {name!r}; known parts: {', '.join(PARTS)}")
    return PARTS[name]()


def load_link_mesh(path: str | PathLike[str], scale: float = 1.0) -> trimesh.Trimesh:
    """A link mesh from STL/OBJ (units: metres after `scale`), checked and repaired
    (`sim.skin.link_mesh`): ConfigError if unreadable, empty or not in metres; a `MeshRepaired`
    warning saying what was repaired."""
    mesh, notes = link_mesh.load_link_mesh(path, scale)
    if notes:
        warnings.warn(
            link_mesh.MeshRepaired(f"link mesh {path} repaired: {', '.join(notes)}"), stacklevel=2
        )
    return mesh


def custom_part(
    mesh_path: str | PathLike[str],
    region: TubeRegion | PlaneRegion,
    tiling: Tiling,
    name: str = "custom",
    scale: float = 1.0,
) -> Part:
    """Sensorize any link mesh: modules of `tiling` over `region` (link frame, m). ConfigError
    names the file when the tiling does not fit the link."""
    link = load_link_mesh(mesh_path, scale)
    try:
        return make_part(name, link, region, tiling, f"custom part from {Path(mesh_path).name}")
    except ConfigError as err:
        raise ConfigError(
            f"link mesh {mesh_path}: its taxels cannot be placed ({err}). Fix: a link shaped, "
            "sized and placed like Baxter's W0 (a tube about the z axis, metres)"
        ) from None


# Baxter W0 (real mesh, ../shared/data/baxter): its body is a rounded square tube about the axis
# through (-0.005, 0, z); 6 rows x 12 modules of the forearm pitch around it, seam at +x (the
# side buttons face -x and stay inside the covered region).
W0_REGION = TubeRegion((-0.005, 0.0, 0.0), (0.0, 0.0, 1.0), (-1.0, 0.0, 0.0), center_m=0.095)
W0_TILING = Tiling(4, 16, col_pitch_mm=22.0, row_pitch_mm=35.4, pitch_mm=TAXEL_PITCH_MM)
