"""Flatten a taxel surface mesh to a 2D tactile map that keeps lengths, areas and neighbours.

Per edge-connected patch: LSCM (least-squares conformal, libigl) initialises ARAP (as-rigid-as-
possible, libigl), which removes LSCM's scale drift on curved skins. A patch whose flat map still
has flipped triangles falls back to LSCM, then to SLIM (symmetric Dirichlet, provably flip-free
from a Tutte embedding). A patch with two or more boundary loops is cut along the shortest path
between its two longest loops when that halves the distortion (a tube opens into a strip; a
patch with a hole keeps it). Each patch is scaled to its 3D area, rotated to its long axis, and
the patches are packed side by side. See docs/flattening.md for the measured distortion.

The map shows the skin as seen from inside the link, as the paper's tactile images do: there a
right hand's thumb lies to the right of its fingers when they point up (rows down), in 77 % of
the real prints of ../shared/data/real_hands (fold 1 / 2: 0.78 / 0.77; the paper's people were
77.8 % right-handed). Seen from outside, every print would be its mirror image.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import igl
import numpy as np
from scipy.sparse import coo_matrix, diags
from scipy.sparse.linalg import spsolve

from tactile.errors import MapError
from tactile.geometry.distortion import (
    DistortionReport,
    distortion_report,
    signed_areas,
    triangle_areas,
)
from tactile.geometry.packing import canonical_map, canonical_patch, shelf_offsets
from tactile.geometry.seams import boundary_loops, face_components, seam_edges, split_vertices
from tactile.geometry.surface import SurfaceMesh

METHODS = ("arap", "lscm")
ARAP_ITERATIONS = 100  # local-global iterations; converged on the iCub layouts (docs)
SLIM_ITERATIONS = 30
CUT_GAIN = 0.5  # a seam is kept when it at least halves the mean |log edge ratio|
CUT_MIN_SCORE = 0.02  # ... and the uncut map is worse than this (2 % mean length error)
MAX_SEAMS = 4


@dataclass(frozen=True)
class Flattening:
    """A flat map of a taxel surface mesh.

    vertex_uv_mm : (V, 2) float64, mm — a taxel on a seam has several vertices
    vertex_taxel : (V,) int64 taxel of each vertex
    faces : (M, 3) int64 into vertex_uv_mm, counter-clockwise (positive signed area)
    taxel_uv_mm : (N, 2) float64, mm — one vertex per taxel; NaN rows for unplaced taxels
    distortion : DistortionReport of the whole map
    n_patches : separately flattened patches packed side by side; seams : cuts made
    """

    vertex_uv_mm: np.ndarray
    vertex_taxel: np.ndarray
    faces: np.ndarray
    taxel_uv_mm: np.ndarray
    distortion: DistortionReport
    n_patches: int
    seams: int


def flatten(positions_m: np.ndarray, mesh: SurfaceMesh, *, method: str = "arap") -> Flattening:
    """Flatten ``mesh`` (a `tactile.geometry.surface.SurfaceMesh`) over taxels positions_m (N, 3) m.

    method : "arap" (LSCM-initialised ARAP, default) or "lscm". Raises MapError on degenerate
    input. Unplaced taxels (in no triangle) get NaN rows in ``taxel_uv_mm``.
    """
    xyz_mm, faces = _check_input(positions_m, mesh, method)
    faces, vertex_taxel = split_vertices(faces)
    label = face_components(faces)
    order = sorted(np.unique(label), key=lambda c: (-(label == c).sum(), faces[label == c].min()))
    patches = [_flatten_patch(xyz_mm, vertex_taxel, faces[label == c], method) for c in order]
    uv, vt, out_faces = seen_from_inside(*_pack(patches, xyz_mm))
    taxel_uv = np.full((len(xyz_mm), 2), np.nan)
    taxel_uv[vt[::-1]] = uv[::-1]  # the first vertex of each taxel wins
    report = distortion_report(xyz_mm[vt], uv, out_faces)
    if report.n_flipped:
        warnings.warn(f"flat map has {report.n_flipped} flipped triangles", stacklevel=2)
    return Flattening(uv, vt, out_faces, taxel_uv, report, len(patches), sum(p[3] for p in patches))


def seen_from_inside(
    uv_mm: np.ndarray, vertex_taxel: np.ndarray, faces: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A packed map (V, 2) mm mirrored across the u axis (v -> max v - v), its faces' winding
    reversed so that they stay counter-clockwise: the skin seen from inside the link (module
    docstring). u, and so the map's long axis and its direction along the link, is kept."""
    v = uv_mm[:, 1]
    return np.column_stack([uv_mm[:, 0], v.max() - v]), vertex_taxel, faces[:, ::-1].copy()


def _check_input(
    positions_m: np.ndarray, mesh: SurfaceMesh, method: str
) -> tuple[np.ndarray, np.ndarray]:
    if method not in METHODS:
        raise MapError(f"unknown flattening method {method!r}; known methods: {', '.join(METHODS)}")
    p = np.asarray(positions_m, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3 or not np.isfinite(p).all():
        raise MapError(f"positions_m must be finite (N, 3) metres, got shape {p.shape}")
    faces = np.asarray(mesh.faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        raise MapError(
            "the surface mesh has no triangles: taxels too sparse or collinear "
            "(raise max_edge_factor in triangulate, or check the layout)"
        )
    if faces.min() < 0 or faces.max() >= len(p):
        raise MapError(
            f"mesh faces index taxels 0..{faces.max()} but only {len(p)} positions given"
        )
    xyz_mm = p * 1e3
    if (triangle_areas(xyz_mm, faces) < 1e-9).any():
        raise MapError(
            "the surface mesh has zero-area triangles (duplicate or collinear taxels); "
            "merge duplicate positions before triangulating"
        )
    return xyz_mm, faces


def _flatten_patch(
    xyz_mm: np.ndarray, vertex_taxel: np.ndarray, faces: np.ndarray, method: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Flatten one patch: (uv (v, 2) mm, taxel (v,), local faces (m, 3), seams cut)."""
    used, local = np.unique(faces, return_inverse=True)
    faces, taxel = local.reshape(-1, 3), vertex_taxel[used]
    if not boundary_loops(faces):
        raise MapError(
            f"{len(taxel)} taxels cover a closed surface (no edge, as on a sphere), which no "
            "map lays flat without a cut. Fix: leave out a strip of taxels so that the "
            "covering has an edge, or map the halves as two layouts"
        )
    uv = parameterize(xyz_mm[taxel], faces, method)
    n_seams = 0
    loops = boundary_loops(faces)
    while len(loops) >= 2 and n_seams < MAX_SEAMS:
        cut = seam_edges(xyz_mm[taxel], faces, loops[0], loops[1])
        if not len(cut):
            break
        cut_faces, orig = split_vertices(faces, cut)
        cut_uv = parameterize(xyz_mm[taxel[orig]], cut_faces, method)
        before = map_score(xyz_mm[taxel], uv, faces)
        if (
            before < CUT_MIN_SCORE
            or map_score(xyz_mm[taxel[orig]], cut_uv, cut_faces) > CUT_GAIN * before
        ):
            break
        faces, taxel, uv, n_seams = cut_faces, taxel[orig], cut_uv, n_seams + 1
        loops = boundary_loops(faces)
    return canonical_patch(uv, xyz_mm[taxel]), taxel, faces, n_seams


def map_score(xyz_mm: np.ndarray, uv_mm: np.ndarray, faces: np.ndarray) -> float:
    """Mean |log(2D / 3D edge length)| of a flat mesh; +inf when a triangle is flipped."""
    report = distortion_report(xyz_mm, uv_mm, faces)
    return np.inf if report.n_flipped else float(np.mean(np.abs(np.log(report.edge_ratio))))


def parameterize(xyz_mm: np.ndarray, faces: np.ndarray, method: str = "arap") -> np.ndarray:
    """Flat coordinates (V, 2) mm of one connected patch, counter-clockwise, area-preserving.

    Tries ``method`` (ARAP from LSCM, or LSCM), then LSCM, then SLIM; the first flip-free result
    wins. If all flip (only possible for a patch that is not a disk), the one with fewest flips.
    """
    candidates = []
    lscm = _normalise(xyz_mm, faces, _lscm(xyz_mm, faces))
    if method == "arap" and np.isfinite(lscm).all():
        candidates.append(lambda: _normalise(xyz_mm, faces, _arap(xyz_mm, faces, lscm)))
    candidates.append(lambda: lscm)
    if len(boundary_loops(faces)) == 1:
        candidates.append(lambda: _normalise(xyz_mm, faces, _slim(xyz_mm, faces)))
    best, best_flips = None, np.inf
    for make in candidates:
        uv = make()
        # a solver that failed (NaN/inf) counts as flipping everything
        flips = int((~(signed_areas(uv, faces) > 0)).sum())
        if flips == 0:
            return uv
        if flips < best_flips:
            best, best_flips = uv, flips
    if best is None or not np.isfinite(best).all():
        raise MapError(
            f"could not flatten a patch of {len(xyz_mm)} taxels and {len(faces)} triangles "
            "(every parameterization failed); check the layout for taxels bridging separate "
            "surfaces, or lower max_edge_factor in triangulate"
        )
    return best


def _normalise(xyz_mm: np.ndarray, faces: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Mirror uv (V, 2) if mostly clockwise, and scale it to the 3D area of the patch."""
    signed = signed_areas(uv, faces).sum()
    if signed < 0:
        uv = uv * np.array([-1.0, 1.0])
    scale = np.sqrt(triangle_areas(xyz_mm, faces).sum() / abs(signed))
    return (uv - uv.mean(axis=0)) * scale


def _lscm(xyz_mm: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """LSCM with the two mutually farthest-ish vertices pinned at their 3D distance."""
    a = int(np.argmax(np.linalg.norm(xyz_mm - xyz_mm.mean(axis=0), axis=1)))
    b = int(np.argmax(np.linalg.norm(xyz_mm - xyz_mm[a], axis=1)))
    d = float(np.linalg.norm(xyz_mm[b] - xyz_mm[a]))
    try:
        uv, _ = igl.lscm(xyz_mm, faces, np.array([a, b]), np.array([[0.0, 0.0], [d, 0.0]]))
    except RuntimeError:  # "igl::lscm failed": a failed solve, as NaN is (`parameterize`)
        return np.full((len(xyz_mm), 2), np.nan)
    return uv


def _arap(xyz_mm: np.ndarray, faces: np.ndarray, uv0: np.ndarray) -> np.ndarray:
    """ARAP parameterization started from uv0 (V, 2); vertex 0 is pinned (fixes translation)."""
    data = igl.ARAPData()
    data.max_iter = ARAP_ITERATIONS
    data.energy = igl.ARAP_ENERGY_TYPE_ELEMENTS  # per-triangle rotations (Liu et al. 2008)
    data.with_dynamics = False  # with dynamics, the inertia term pins the LSCM start
    pinned = np.zeros(1, np.int32)
    igl.arap_precomputation(xyz_mm, faces, 2, pinned, data)
    return igl.arap_solve(uv0[:1].copy(), data, np.ascontiguousarray(uv0))


def _slim(xyz_mm: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """SLIM (symmetric Dirichlet) from a Tutte embedding: flip-free for a disk patch."""
    uv0 = _tutte(xyz_mm, faces)
    data = igl.slim_precompute(
        np.asfortranarray(xyz_mm),
        np.asfortranarray(faces, dtype=np.int32),
        np.asfortranarray(uv0),
        igl.SYMMETRIC_DIRICHLET,
        np.zeros(0, np.int32),
        np.zeros((0, 2), order="F"),
        0.0,
    )
    return np.asarray(igl.slim_solve(data, SLIM_ITERATIONS))


def _tutte(xyz_mm: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Tutte embedding (V, 2): boundary on a circle by arc length, uniform interior weights."""
    loop = boundary_loops(faces)[0]
    step = np.linalg.norm(xyz_mm[np.roll(loop, -1)] - xyz_mm[loop], axis=1)
    angle = 2 * np.pi * np.concatenate([[0.0], np.cumsum(step)[:-1]]) / step.sum()
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    n = len(xyz_mm)
    adj = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)).tocsr()
    adj = ((adj + adj.T) > 0).astype(float)
    lap = (diags(np.asarray(adj.sum(axis=1)).ravel()) - adj).tocsr()
    inner = np.setdiff1d(np.arange(n), loop)
    uv = np.zeros((n, 2))
    uv[loop] = np.column_stack([np.cos(angle), np.sin(angle)])
    rhs = -lap[inner][:, loop] @ uv[loop]
    uv[inner] = np.reshape(spsolve(lap[inner][:, inner].tocsc(), rhs), (len(inner), 2))
    return uv


def _pack(
    patches: list[tuple[np.ndarray, np.ndarray, np.ndarray, int]], xyz_mm: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pack flat patches side by side; returns uv (V, 2) mm, vertex_taxel (V,), faces (M, 3)."""
    sizes = np.array([np.ptp(uv, axis=0) for uv, *_ in patches])
    offsets = shelf_offsets(sizes)
    uvs, taxels, faces, base = [], [], [], 0
    for (uv, taxel, f, _), offset in zip(patches, offsets, strict=True):
        uvs.append(uv - uv.min(axis=0) + offset)
        taxels.append(taxel)
        faces.append(f + base)
        base += len(uv)
    uv, vt = np.concatenate(uvs), np.concatenate(taxels).astype(np.int64)
    return canonical_map(uv, xyz_mm[vt]), vt, np.concatenate(faces).astype(np.int64)
