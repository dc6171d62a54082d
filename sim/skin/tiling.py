"""Tile triangular skin modules over a region of a link mesh and return a `TaxelLayout`.

A module is the iCub/Schmitz triangle: 12 pads at fixed offsets (../shared/data/README.md), scaled
so that the nearest-neighbour pad distance equals the stated taxel pitch. Modules sit on a flat
lattice of alternating up/down triangles (flat coordinates (a, b) in mm), which a region maps onto
the surface:

- `TubeRegion`: a around the outer contour of cross-sections normal to an axis (arc length, so
  the lattice keeps its spacing around rounded corners), b along the axis;
- `PlaneRegion`: a lattice on a plane, each pad moved to the closest point of the mesh.

Normals are area-weighted face normals around each pad (within 2 mm), oriented outward.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from tactile.errors import ConfigError
from tactile.geometry.layout import TaxelLayout

ICUB_PADS_MM = np.array(
    [
        [6.533, 0.0],
        [9.8, -5.66],
        [3.267, -5.66],
        [0.0, 0.0],
        [-3.267, -5.66],
        [-9.8, -5.66],
        [-6.533, -3.75],
        [-6.533, 0.0],
        [-3.267, 5.66],
        [0.0, 11.317],
        [0.0, 7.507],
        [3.267, 5.66],
    ]
)  # mm, pad i of an upright triangle, centre at the origin (pads 6 and 10 are thermal on iCub)
ICUB_PITCH_MM = 6.533  # nearest-neighbour distance of the tactile pads above
PADS_PER_MODULE = 12


def module_pads_mm(pitch_mm: float = 8.0) -> np.ndarray:
    """Pad offsets (12, 2) mm of an upright module scaled to nearest-neighbour distance pitch_mm."""
    return ICUB_PADS_MM * (pitch_mm / ICUB_PITCH_MM)


def module_lattice(
    n_rows: int, n_cols: int, col_pitch_mm: float, row_pitch_mm: float
) -> tuple[np.ndarray, np.ndarray]:
    """Centroids (M, 2) mm and up-flags (M,) of an alternating up/down triangle lattice.

    Rows run along x; consecutive triangles in a row are col_pitch_mm apart and alternate
    orientation; rows are row_pitch_mm apart. Up triangles sit a third of a row above the row
    base, down ones two thirds. Centred so that the centroid bounding box is symmetric about 0.
    """
    r, c = np.meshgrid(np.arange(n_rows), np.arange(n_cols), indexing="ij")
    up = ((r + c) % 2 == 0).ravel()
    x = c.ravel() * col_pitch_mm
    y = (r.ravel() + np.where(up, 1 / 3, 2 / 3)) * row_pitch_mm
    centres = np.column_stack([x, y])
    return centres - 0.5 * (centres.min(axis=0) + centres.max(axis=0)), up


def place_pads(
    centres_mm: np.ndarray, up: np.ndarray, pads_mm: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pads of every module: flat positions (M·12, 2) mm, module ids (M·12,), channel ids.

    Down modules are the up module turned by 180°. Channel = module · 12 + pad (iCub order).
    """
    sign = np.where(up, 1.0, -1.0)[:, None, None]
    flat = centres_mm[:, None, :] + sign * pads_mm[None]
    m = centres_mm.shape[0]
    modules = np.repeat(np.arange(m), PADS_PER_MODULE)
    return flat.reshape(-1, 2), modules, np.arange(m * PADS_PER_MODULE)


def _unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _frame(axis: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Orthonormal (e1, e2, axis) with e1 the part of ref normal to axis."""
    axis = _unit(axis)
    e1 = _unit(ref - np.dot(ref, axis) * axis)
    return e1, np.cross(axis, e1), axis


def _candidates(
    mesh: trimesh.Trimesh, points_m: np.ndarray, k: int
) -> tuple[np.ndarray, np.ndarray]:
    """The k triangles (K, k) whose bounding boxes are nearest each point (a lower bound of the
    distance, so long slender triangles are not missed) and the closest points on them (K, k, 3)."""
    k = min(k, len(mesh.faces))
    tri = mesh.triangles
    lo, hi = tri.min(axis=1), tri.max(axis=1)
    cand = np.empty((len(points_m), k), dtype=np.int64)
    for start in range(0, len(points_m), 64):
        p = points_m[start : start + 64, None, :]
        gap = np.maximum(np.maximum(lo[None] - p, p - hi[None]), 0.0)
        cand[start : start + 64] = np.argpartition(np.einsum("kfd,kfd->kf", gap, gap), k - 1)[:, :k]
    pts = trimesh.triangles.closest_point(tri[cand.ravel()], np.repeat(points_m, k, axis=0))
    return cand, pts.reshape(-1, k, 3)


def closest_on_mesh(
    mesh: trimesh.Trimesh, points_m: np.ndarray, k: int = 24
) -> tuple[np.ndarray, np.ndarray]:
    """Closest points (K, 3) m on the mesh and their triangles (K,), among the k triangles with the
    nearest centroids (exact for meshes whose triangles are small next to their spacing)."""
    cand, pts = _candidates(mesh, points_m, k)
    best = np.argmin(np.linalg.norm(pts - points_m[:, None], axis=2), axis=1)
    rows = np.arange(len(points_m))
    return pts[rows, best], cand[rows, best]


def project(
    mesh: trimesh.Trimesh, points_m: np.ndarray, radius_m: float = 2e-3, k: int = 24
) -> tuple[np.ndarray, np.ndarray]:
    """Closest mesh points (K, 3) m and unit normals (K, 3) there: the area-weighted mean normal
    of the faces within radius_m (smooth on fine curves, exact on flat faces of big triangles)."""
    cand, pts = _candidates(mesh, points_m, k)
    dist = np.linalg.norm(pts - points_m[:, None], axis=2)
    best = np.argmin(dist, axis=1)
    closest = pts[np.arange(len(points_m)), best]
    near = np.linalg.norm(pts - closest[:, None], axis=2) <= radius_m
    w = np.where(near, mesh.area_faces[cand], 0.0)
    n = np.einsum("kj,kjd->kd", w, mesh.face_normals[cand])
    return closest, n / np.linalg.norm(n, axis=1, keepdims=True)


def outward(normals: np.ndarray, points_m: np.ndarray, inside_m: np.ndarray) -> np.ndarray:
    """Flip normals (K, 3) that point towards inside_m ((3,) or (K, 3) points inside the link)."""
    flip = np.sum(normals * (points_m - inside_m), axis=1) < 0
    return np.where(flip[:, None], -normals, normals)


def polar_contour(segments_2d: np.ndarray, n_angles: int) -> tuple[np.ndarray, np.ndarray]:
    """Outermost radius r (K,) along rays at angles theta (K,) in [-π, π) from the origin.

    segments_2d : (S, 2, 2) line segments of one cross-section, in the (e1, e2) plane, m.
    Rays that hit nothing get NaN.
    """
    theta = np.linspace(-np.pi, np.pi, n_angles, endpoint=False)
    d = np.column_stack([np.cos(theta), np.sin(theta)])  # (K, 2)
    p, e = segments_2d[:, 0], segments_2d[:, 1] - segments_2d[:, 0]  # (S, 2)
    den = d[:, None, 0] * e[None, :, 1] - d[:, None, 1] * e[None, :, 0]  # (K, S)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (p[None, :, 0] * e[None, :, 1] - p[None, :, 1] * e[None, :, 0]) / den
        u = (p[None, :, 0] * d[:, None, 1] - p[None, :, 1] * d[:, None, 0]) / den
    ok = (np.abs(den) > 1e-15) & (u >= 0) & (u <= 1) & (t > 0)
    r = np.where(ok, t, -np.inf).max(axis=1)
    return theta, np.where(np.isfinite(r), r, np.nan)


def fill_gaps(theta: np.ndarray, r: np.ndarray, max_gap_rad: float) -> np.ndarray:
    """Interpolate (periodically) over rays that missed an open mesh's slits, if all gaps are
    narrower than max_gap_rad; otherwise return r unchanged (NaNs left for the caller)."""
    miss = np.isnan(r)
    if not miss.any() or miss.all():
        return r
    step = theta[1] - theta[0]
    runs = np.diff(np.flatnonzero(np.diff(np.concatenate([[0], miss, [0]]).astype(int))))[::2]
    if runs.max() * step > max_gap_rad:
        return r
    good = ~miss
    return np.interp(theta, theta[good], r[good], period=2 * np.pi)


def arc_length(theta: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Arc length (K,) m along the closed polar curve, zero at theta = 0."""
    xy = np.column_stack([r * np.cos(theta), r * np.sin(theta)])
    step = np.linalg.norm(np.diff(xy, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(step)])
    return s - np.interp(0.0, theta, s)


@dataclass(frozen=True)
class TubeRegion:
    """Cover a tube-like link around an axis: flat a = arc length around, b = height along axis.

    origin_m : a point on the axis; axis : its direction; ref_dir : where a = 0 lies (from the
    axis); center_m : height of b = 0 along the axis from origin_m. Lattice flat coordinates map
    to a ∈ (-half perimeter, +half perimeter), so the uncovered seam faces -ref_dir.
    """

    origin_m: tuple[float, float, float]
    axis: tuple[float, float, float]
    ref_dir: tuple[float, float, float]
    center_m: float
    n_angles: int = 1440
    max_gap_rad: float = 0.35  # slits in open meshes narrower than this are bridged

    def map(self, mesh: trimesh.Trimesh, flat_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Flat (K, 2) mm -> positions (K, 3) m on the mesh and outward normals (K, 3)."""
        e1, e2, axis = _frame(np.asarray(self.axis), np.asarray(self.ref_dir))
        origin = np.asarray(self.origin_m, dtype=float)
        heights = self.center_m + flat_mm[:, 1] * 1e-3
        levels, inverse = np.unique(np.round(heights, 9), return_inverse=True)
        lines, to_3d, _ = trimesh.intersections.mesh_multiplane(mesh, origin, axis, levels)
        out = np.empty((flat_mm.shape[0], 3))
        for i, h in enumerate(levels):
            if len(lines[i]) == 0:
                raise ConfigError(f"TubeRegion: the mesh has no cross-section at height {h:.4f} m")
            flat2 = np.reshape(lines[i], (-1, 2))
            seg3 = trimesh.transform_points(
                np.column_stack([flat2, np.zeros(len(flat2))]), to_3d[i]
            )
            rel = seg3.reshape(-1, 2, 3) - (origin + h * axis)
            seg2 = np.stack([rel @ e1, rel @ e2], axis=-1)
            pick = np.flatnonzero(inverse == i)
            ring = self._ring(seg2, h, flat_mm[pick, 0] * 1e-3)
            out[pick] = origin + h * axis + ring[:, :1] * e1 + ring[:, 1:] * e2
        centre = origin + np.outer(heights, axis)
        out, normals = project(mesh, out)  # no-op on closed meshes; snaps pads over open slits
        return out, outward(normals, out, centre)

    def _ring(self, seg2: np.ndarray, h: float, a_m: np.ndarray) -> np.ndarray:
        """Points (K, 2) m in the (e1, e2) plane at arc lengths a_m (K,) m around the section."""
        theta, r = polar_contour(seg2, self.n_angles)
        r = fill_gaps(theta, r, self.max_gap_rad)
        if np.isnan(r).any():
            raise ConfigError(f"TubeRegion: the axis is not inside the section at {h:.4f} m")
        theta_c = np.append(theta, np.pi)
        s = arc_length(theta_c, np.append(r, r[0]))
        a = a_m
        if a.min() < s[0] or a.max() > s[-1]:
            raise ConfigError(
                f"TubeRegion: pads span {np.ptp(a) * 1e3:.0f} mm around but the section at "
                f"{h:.4f} m is {(s[-1] - s[0]) * 1e3:.0f} mm long; use fewer modules"
            )
        th = np.interp(a, s, theta_c)
        rr = np.interp(th, theta_c, np.append(r, r[0]))
        return rr[:, None] * np.column_stack([np.cos(th), np.sin(th)])


@dataclass(frozen=True)
class PlaneRegion:
    """Cover a near-flat face: flat (a, b) on the plane through origin_m spanned by a_dir and
    normal × a_dir, each pad then moved to the closest mesh point; normal points outward."""

    origin_m: tuple[float, float, float]
    normal: tuple[float, float, float]
    a_dir: tuple[float, float, float]

    def map(self, mesh: trimesh.Trimesh, flat_mm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Flat (K, 2) mm -> positions (K, 3) m on the mesh and outward normals (K, 3)."""
        e1, e2, n = _frame(np.asarray(self.normal), np.asarray(self.a_dir))
        plane = np.asarray(self.origin_m) + 1e-3 * (
            np.outer(flat_mm[:, 0], e1) + np.outer(flat_mm[:, 1], e2)
        )
        closest, normals = project(mesh, plane)
        return closest, outward(normals, closest, closest - n)


@dataclass(frozen=True)
class Tiling:
    """How modules are laid out: lattice size and pitches (mm), pad pitch (mm), lattice turn."""

    n_rows: int
    n_cols: int
    col_pitch_mm: float
    row_pitch_mm: float
    pitch_mm: float = 8.0
    transpose: bool = False  # swap lattice (x, y) -> flat (b, a): rows then run along b
    # Which lattice slots hold a module: one string per row, top row first, "X" = module,
    # "." = deliberately uncovered; empty = all slots.
    keep: tuple[str, ...] = ()

    def slots(self) -> np.ndarray:
        """(n_rows · n_cols,) bool, row-major from the bottom row: which slots hold a module."""
        if not self.keep:
            return np.ones(self.n_rows * self.n_cols, dtype=bool)
        rows = [r.strip() for r in self.keep]
        if len(rows) != self.n_rows or any(len(r) != self.n_cols for r in rows):
            raise ConfigError(
                f"Tiling.keep must be {self.n_rows} strings of {self.n_cols} 'X'/'.' characters"
            )
        return np.array([ch == "X" for r in rows[::-1] for ch in r])

    def flat(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pads in flat coordinates (K, 2) mm, module ids (K,), channel ids (K,)."""
        if min(self.n_rows, self.n_cols) < 1 or min(self.col_pitch_mm, self.row_pitch_mm) <= 0:
            raise ConfigError(f"Tiling needs >= 1 row and column and positive pitches; got {self}")
        centres, up = module_lattice(self.n_rows, self.n_cols, self.col_pitch_mm, self.row_pitch_mm)
        slots = self.slots()
        centres, up = centres[slots], up[slots]
        centres = centres - 0.5 * (centres.min(axis=0) + centres.max(axis=0))
        flat, modules, channels = place_pads(centres, up, module_pads_mm(self.pitch_mm))
        return (flat[:, ::-1] if self.transpose else flat), modules, channels


def tile(
    mesh: trimesh.Trimesh, region: TubeRegion | PlaneRegion, tiling: Tiling, name: str = ""
) -> tuple[TaxelLayout, np.ndarray]:
    """Tile modules over a region of the mesh.

    Returns the layout (link frame, m) and the flat lattice positions (K, 2) mm."""
    flat, modules, channels = tiling.flat()
    positions, normals = region.map(mesh, flat)
    layout = TaxelLayout(
        positions_m=positions,
        normals=normals,
        module_ids=modules,
        channel_ids=channels,
        n_channels=int(channels.size),
        name=name,
    )
    return layout, flat
