"""Where contactors press: one placement policy for hands and non-hands, and surface frames.

Policy. Every contactor (hand, object, body part) is aimed at a taxel drawn with probability
proportional to its *coverage*: the number of taxels within `AIM_RADIUS_MM` (a hand's half
length) on the part's flat lattice; on a part with aim bands (the default skin, where the
paper's people grasped the top face's middle at one place along the link:
`sim.skin.parts.PAPER_AIM_BAND_MM`, `PAPER_AIM_ALONG_MM`) only there.
Operators and objects touch the skin, not the bare link, and a classifier must not learn the
class from *where* the contact is: the same draw serves both
classes (non-hand plans leave ``site_uv`` None and the runner draws with `draw_aim_taxel`; hand
plans draw the same way and arrange the hand around the aim, `sim.contactors.interactions`).

Surface frames. A lattice point (u, v) mm anywhere on the part, not only at a taxel, maps to the
link surface: the nearest taxel plus the local linear map from lattice to 3D, then the closest
point of the link mesh and that face's normal (`surface_point`). `edge_distance_m` walks along a
tangent until the surface turns away (the start of an edge a grasp wraps around).
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.spatial import cKDTree

from sim.skin.parts import Part

AIM_RADIUS_MM = 80.0  # coverage radius: hand-sized (palm centre to fingertips 0.7 x 18 cm), mm
JACOBIAN_RADIUS_MM = 30.0  # neighbourhood of the local lattice -> 3D linear fit, mm
EDGE_ANGLE_DEG = 35.0  # the surface has turned into an edge when its normal is this far off
EDGE_STEP_M = 0.004  # march step along the surface, m
SURFACE_EDGE_M = 0.004  # longest edge of the subdivided link mesh used for surface look-ups, m


@lru_cache(maxsize=8)
def coverage(part: Part) -> np.ndarray:
    """(N,) float: taxels within `AIM_RADIUS_MM` of each taxel on the flat lattice (incl. it)."""
    tree = cKDTree(part.flat_mm)
    return np.array([len(n) for n in tree.query_ball_point(part.flat_mm, AIM_RADIUS_MM)], float)


def aim_weights(part: Part) -> np.ndarray:
    """(N,) float: `coverage`, zero outside the part's aim bands (``Part.aim_band_mm``: the taxels
    within that distance of the middle of the skin's first flat coordinate, around a tube;
    ``Part.aim_along_mm``: of its second, along the link)."""
    w = coverage(part)
    for k, band in enumerate((part.aim_band_mm, part.aim_along_mm)):
        if band is not None:
            a = part.flat_mm[:, k]
            w = w * (np.abs(a - 0.5 * (a.min() + a.max())) <= band)
    return w


def draw_aim_taxel(part: Part, rng: np.random.Generator) -> int:
    """A taxel drawn with probability proportional to `aim_weights` (the shared placement
    policy)."""
    w = aim_weights(part)
    return int(rng.choice(part.n_taxels, p=w / w.sum()))


def link_axis(part: Part) -> np.ndarray:
    """(3,) unit direction in which the flat lattice's second coordinate grows (the link axis of
    a tube part): least-squares gradient of taxel positions with respect to flat v."""
    return _link_axis(part).copy()


@lru_cache(maxsize=8)
def _link_axis(part: Part) -> np.ndarray:
    design = np.column_stack([part.flat_mm, np.ones(part.n_taxels)])
    coef, *_ = np.linalg.lstsq(design, part.layout.positions_m, rcond=None)
    return coef[1] / np.linalg.norm(coef[1])


def lattice_jacobian(part: Part, taxel: int) -> np.ndarray:
    """(3, 2) m per mm: local linear map from lattice displacement to 3D at ``taxel``."""
    flat = part.flat_mm
    near = np.flatnonzero(np.linalg.norm(flat - flat[taxel], axis=1) < JACOBIAN_RADIUS_MM)
    rel = np.column_stack([flat[near] - flat[taxel], np.ones(near.size)])
    coef, *_ = np.linalg.lstsq(rel, part.layout.positions_m[near], rcond=None)
    return coef[:2].T


@lru_cache(maxsize=8)
def _vertex_tree(part: Part):
    """KD-tree over the link mesh subdivided to `SURFACE_EDGE_M` edges, and its vertex normals
    (a coarse mesh, e.g. a box's 8 corners, would give corner normals on a face)."""
    dense = part.link.subdivide_to_size(SURFACE_EDGE_M)
    return cKDTree(np.asarray(dense.vertices)), np.asarray(dense.vertex_normals)


def project(part: Part, point_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(point (3,) m on the link surface, outward unit normal (3,)) near ``point_m`` (3,): the
    projection on the tangent plane of the nearest vertex of the subdivided link mesh, with its
    (smooth: averaged over the faces around it) normal."""
    tree, normals = _vertex_tree(part)
    _, i = tree.query(point_m)
    n = normals[i]
    p = np.asarray(point_m, float)
    return p - ((p - tree.data[i]) @ n) * n, n.copy()


def surface_point(part: Part, uv_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(position (3,) m, outward normal (3,)) of the link surface under lattice point uv (mm)."""
    uv = np.asarray(uv_mm, float)
    k = int(np.argmin(np.sum((part.flat_mm - uv) ** 2, axis=1)))
    guess = part.layout.positions_m[k] + lattice_jacobian(part, k) @ (uv - part.flat_mm[k])
    return project(part, guess)


def edge_distance_m(
    part: Part, pos_m: np.ndarray, normal: np.ndarray, direction: np.ndarray, max_m: float
) -> float:
    """Distance (m) walked from ``pos_m`` along the surface in tangent ``direction`` (3,) until the
    normal is `EDGE_ANGLE_DEG` off ``normal`` (3,); ``max_m`` if it never turns that far."""
    cos_edge = np.cos(np.deg2rad(EDGE_ANGLE_DEG))
    p, d = np.asarray(pos_m, float), np.asarray(direction, float)
    for k in range(1, int(max_m / EDGE_STEP_M) + 1):
        p, n = project(part, p + EDGE_STEP_M * d)
        if n @ normal < cos_edge:
            return (k - 1) * EDGE_STEP_M
        d = d - (d @ n) * n
        d /= np.linalg.norm(d)
    return max_m
