"""Rasterisation of a flat triangle mesh onto the tactile-map pixel grid (pure functions).

The grid has one pixel per ``step_mm``; pixel (r, c) has its centre at
``u = u_min + (c + 0.5) * step`` and ``v = v_max - (r + 0.5) * step`` so that the image looks like
the uv plot (v up). Each pixel centre inside a triangle gets the barycentric weights of the
triangle's three vertices (Albini & Cannata 2020, eq. K_rc = (A_kj p_h + A_hj p_k + A_hk p_j) / A);
the weights form a sparse (pixels inside × taxels) interpolation matrix, the look-up table.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from tactile.errors import MapError

INSIDE_TOL = 1e-10  # barycentric tolerance: pixel centres on an edge belong to the mesh
GREY_TOL = 1e-9  # grey levels: 254.9999999999 (round-off of a sum of weights) counts as 255


def check_array(
    values: object, name: str, shape: tuple[int | None, ...], kind: type, allow_nan: bool = False
) -> np.ndarray:
    """Validated array: shape (None = any), int64 indices or finite float64 (NaN if allowed)."""
    arr = np.asarray(values)
    ok = arr.ndim == len(shape)
    ok = ok and all(s in (None, n) for s, n in zip(shape, arr.shape, strict=True))
    if not ok:
        want = "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"
        raise MapError(f"{name} must have shape {want}, got {arr.shape}")
    if kind is int:
        if arr.size and not np.issubdtype(arr.dtype, np.integer):
            raise MapError(f"{name} must hold integer indices, got dtype {arr.dtype}")
        return arr.astype(np.int64)
    arr = arr.astype(np.float64)
    finite = np.isfinite(arr) | (np.isnan(arr) if allow_nan else False)
    if not finite.all():
        row = int(np.flatnonzero(~finite.reshape(len(arr), -1).all(axis=1))[0])
        raise MapError(f"{name} row {row} is not finite; remove or fix that entry")
    return arr


def check_indices(idx: np.ndarray, name: str, n: int, target: str) -> None:
    """Raise MapError unless every index lies in 0..n-1."""
    if idx.size and (idx.min() < 0 or idx.max() >= n):
        raise MapError(f"{name} must index {target} in 0..{n - 1}, got {idx.min()}..{idx.max()}")


def check_flat_mesh(
    positions_m: object, vertex_uv_mm: object, vertex_taxel: object, faces: object
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Validated (positions (N, 3), vertex uv (V, 2), vertex taxel (V,), faces (M, 3))."""
    pos = check_array(positions_m, "positions_m", (None, 3), float)
    uv_v = check_array(vertex_uv_mm, "vertex_uv_mm", (None, 2), float)
    v_taxel = check_array(vertex_taxel, "vertex_taxel", (len(uv_v),), int)
    tri = check_array(faces, "faces", (None, 3), int)
    check_indices(v_taxel, "vertex_taxel", len(pos), "taxels")
    check_indices(tri, "faces", len(uv_v), "vertices")
    if len(tri) == 0:
        raise MapError("faces is empty: the flat map needs at least one triangle")
    return pos, uv_v, v_taxel, tri


def taxel_uv(vertex_uv_mm: np.ndarray, vertex_taxel: np.ndarray, n_taxels: int) -> np.ndarray:
    """uv of each taxel: its first vertex (NaN when it has none).

    Returns
    -------
    uv : (N, 2) float, mm.
    """
    uv = np.full((n_taxels, 2), np.nan)
    taxels, first = np.unique(vertex_taxel, return_index=True)
    uv[taxels] = vertex_uv_mm[first]
    return uv


def grid_geometry(vertex_uv_mm: np.ndarray, step_mm: float) -> tuple[np.ndarray, tuple[int, int]]:
    """Origin and shape of the pixel grid covering the flat map.

    Parameters
    ----------
    vertex_uv_mm : (V, 2) float, mm — finite vertex coordinates.
    step_mm : float, mm — pixel size.

    Returns
    -------
    origin_mm : (2,) float, mm — (u_min, v_max), the top-left corner of the grid.
    shape : (H, W) — H = ceil((v_max - v_min) / step), W = ceil((u_max - u_min) / step), >= 1.
    """
    lo, hi = vertex_uv_mm.min(axis=0), vertex_uv_mm.max(axis=0)
    extent = np.round((hi - lo) / step_mm, 9)  # 247.0000000001 mm is 247 pixels, not 248
    width, height = (max(1, math.ceil(x)) for x in extent)
    return np.array([lo[0], hi[1]]), (height, width)


def pixel_centers(origin_mm: np.ndarray, shape: tuple[int, int], step_mm: float) -> np.ndarray:
    """uv of every pixel centre.

    Returns
    -------
    centers : (H, W, 2) float, mm — [..., 0] = u (grows with column), [..., 1] = v (falls with row).
    """
    u = origin_mm[0] + (np.arange(shape[1]) + 0.5) * step_mm
    v = origin_mm[1] - (np.arange(shape[0]) + 0.5) * step_mm
    uu, vv = np.meshgrid(u, v)
    return np.stack([uu, vv], axis=-1)


def _candidates(
    tri_uv: np.ndarray, origin_mm: np.ndarray, shape: tuple[int, int], step_mm: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(triangle, row, column) of every pixel in each triangle's bounding box (+1 pixel margin)."""
    col = (tri_uv[..., 0] - origin_mm[0]) / step_mm - 0.5
    row = (origin_mm[1] - tri_uv[..., 1]) / step_mm - 0.5
    c_lo = np.clip(np.floor(col.min(axis=1)).astype(np.int64), 0, shape[1] - 1)
    c_hi = np.clip(np.ceil(col.max(axis=1)).astype(np.int64), 0, shape[1] - 1)
    r_lo = np.clip(np.floor(row.min(axis=1)).astype(np.int64), 0, shape[0] - 1)
    r_hi = np.clip(np.ceil(row.max(axis=1)).astype(np.int64), 0, shape[0] - 1)
    n_cols = c_hi - c_lo + 1
    counts = (r_hi - r_lo + 1) * n_cols
    tri = np.repeat(np.arange(len(tri_uv)), counts)
    local = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    return tri, r_lo[tri] + local // n_cols[tri], c_lo[tri] + local % n_cols[tri]


def barycentric(tri_uv: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Barycentric coordinates of points in triangles, as ratios of signed sub-triangle areas.

    Parameters
    ----------
    tri_uv : (P, 3, 2) float — the triangle of each point (any orientation, non-degenerate).
    points : (P, 2) float.

    Returns
    -------
    weights : (P, 3) float — weight of each corner; sums to 1; all >= 0 inside the triangle.
    """
    d = tri_uv - points[:, None, :]  # corners relative to the point
    x, y = d[..., 0], d[..., 1]
    sub = x[:, [1, 2, 0]] * y[:, [2, 0, 1]] - x[:, [2, 0, 1]] * y[:, [1, 2, 0]]
    return sub / sub.sum(axis=1, keepdims=True)


def locate_pixels(
    vertex_uv_mm: np.ndarray,
    faces: np.ndarray,
    origin_mm: np.ndarray,
    shape: tuple[int, int],
    step_mm: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Triangle and barycentric weights of every pixel centre that lies inside the mesh.

    A pixel covered by several triangles (shared edges, or overlaps from a bad flattening) takes
    the one it is deepest inside (largest smallest weight). Degenerate triangles cover nothing.

    Parameters
    ----------
    vertex_uv_mm : (V, 2) float, mm. faces : (M, 3) int, vertex indices.
    origin_mm, shape, step_mm : the grid (see :func:`grid_geometry`).

    Returns
    -------
    pixels : (P,) int64 — flat pixel indices r * W + c, increasing.
    face : (P,) int64 — containing triangle of each pixel.
    weights : (P, 3) float64 — barycentric weights of the triangle's corners faces[face].
    """
    tri_uv = vertex_uv_mm[faces]
    e1, e2 = tri_uv[:, 1] - tri_uv[:, 0], tri_uv[:, 2] - tri_uv[:, 0]
    area2 = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    good = np.flatnonzero(area2 > 1e-12 * max(float(area2.max(initial=0.0)), 1e-300))
    tri, row, col = _candidates(tri_uv[good], origin_mm, shape, step_mm)
    centers = np.column_stack(
        [origin_mm[0] + (col + 0.5) * step_mm, origin_mm[1] - (row + 0.5) * step_mm]
    )
    weights = barycentric(tri_uv[good][tri], centers)
    depth = weights.min(axis=1)
    keep = depth >= -INSIDE_TOL
    pixel = row[keep] * shape[1] + col[keep]
    order = np.lexsort((-depth[keep], pixel))
    pixel, first = np.unique(pixel[order], return_index=True)
    pick = np.flatnonzero(keep)[order[first]]
    return pixel, good[tri[pick]], weights[pick]


def interpolation_matrix(
    pixels: np.ndarray,
    corner_taxels: np.ndarray,
    weights: np.ndarray,
    n_pixels: int,
    n_taxels: int,
    dtype: type = np.float64,
) -> sp.csr_matrix:
    """Sparse look-up table mapping taxel pressures to every pixel of the grid.

    Parameters
    ----------
    pixels : (P,) int, increasing — flat indices of the pixels inside the mesh.
    corner_taxels : (P, 3) int — taxel of each corner of each pixel's triangle.
    weights : (P, 3) float — barycentric weights.
    n_pixels, n_taxels : H * W rows and N columns.

    Returns
    -------
    matrix : (H * W, N) CSR — 3 non-zeros in a row inside the mesh (fewer where corners share a
        taxel), none outside; ``matrix @ p`` is the flattened interpolated image.
    """
    indptr = np.zeros(n_pixels + 1, dtype=np.int64)
    indptr[1:] = np.cumsum(np.bincount(pixels, minlength=n_pixels) * 3)
    matrix = sp.csr_matrix(
        (weights.ravel().astype(dtype), corner_taxels.ravel(), indptr), shape=(n_pixels, n_taxels)
    )
    matrix.sum_duplicates()
    return matrix


def grey_levels(values: np.ndarray, max_pressure: np.ndarray) -> np.ndarray:
    """The paper's grey levels ``floor(255 * K / max p + GREY_TOL)``, clipped to 0..255.

    ``GREY_TOL`` only absorbs round-off of the barycentric sums: a uniform field (or a pixel on
    the most pressed taxel) gives 255, not 254. ``values`` is overwritten.

    Parameters
    ----------
    values : (..., H, W) float — interpolated pressures K (modified in place).
    max_pressure : (...) float — per-frame maximum taxel pressure; frames with max <= 0 give 0.

    Returns
    -------
    grey : (..., H, W) uint8.
    """
    scale = np.where(max_pressure > 0, max_pressure, np.inf)[..., None, None]
    np.multiply(values, 255.0, out=values)
    np.divide(values, scale, out=values)
    np.add(values, GREY_TOL, out=values)
    np.clip(values, 0.0, 255.0, out=values)
    return values.astype(np.uint8)  # truncation = floor for values >= 0
