"""Corrupted maps of the robustness tests (torch-free): blind spots (Test A) and taxel removal
with a rebuilt map (Test B), with the ground truth each corruption implies.

Test A: spot centres are random placed taxels; taxels within ``radius_mm`` of a centre (on the
flat map) read zero, and ground-truth pixels whose centre lies within ``radius_mm`` of a spot
centre are set to background. Test B: the map is rebuilt from the kept taxels
(``TactileMap.build(layout.subset(keep))``); each pixel of the rebuilt map is traced back to the
full map through its triangle's kept taxels (barycentric, piecewise affine), and takes the full
map's ground truth there. Pixels outside the rebuilt map's coverage are not counted
(``IGNORE``), and ``p_d`` is the share of ground-truth hand pixels inside the full map's mesh
that the kept taxels' triangles no longer cover (hand pixels of the image's dilation past the
mesh count in neither).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tactile.errors import ConfigError
from tactile.geometry.layout import TaxelLayout
from tactile.images import raster
from tactile.images.labels import IGNORE
from tactile.images.tactile_map import TactileMap

SEAM_AREA_RATIO = 4.0  # a triangle whose full-map area differs more than this spans a seam


def spot_centres_mm(uv: np.ndarray, n_spots: int, rng: np.random.Generator) -> np.ndarray:
    """Centres (n_spots, 2) mm: distinct random placed taxels (the draw of
    ``tactile.images.faults.blind_spots``, which does not return them). uv : (N, 2) mm, NaN
    unplaced."""
    placed = np.flatnonzero(np.isfinite(uv).all(axis=1))
    if not 0 <= n_spots <= len(placed):
        raise ConfigError(f"n_spots must be in 0..{len(placed)} (placed taxels), got {n_spots}")
    return uv[rng.choice(placed, size=n_spots, replace=False)]


def within_mm(points: np.ndarray, centres: np.ndarray, radius_mm: float) -> np.ndarray:
    """(...) bool: points (..., 2) mm within ``radius_mm`` of any centre (M, 2) mm (NaN: no)."""
    d2 = ((points[..., None, :] - centres) ** 2).sum(axis=-1)
    return (d2 <= radius_mm**2).any(axis=-1)


def spot_pattern(
    tmap: TactileMap, n_spots: int, radius_mm: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """One Test A pattern: (blind taxels (N,) bool, blind pixels (H, W) bool)."""
    if not radius_mm >= 0:
        raise ConfigError(f"radius_mm must be >= 0 mm, got {radius_mm}")
    centres = spot_centres_mm(tmap.uv, n_spots, rng)
    blind = within_mm(np.nan_to_num(tmap.uv, nan=np.inf), centres, radius_mm)
    return blind, within_mm(tmap.pixel_centers(), centres, radius_mm)


@dataclass(frozen=True, eq=False)
class RemovedMap:
    """The map of the taxels left after a removal, and how it relates to the full map.

    fraction : float, share of taxels removed. keep : (K,) int64 kept taxels (full layout).
    tmap : TactileMap over the kept taxels. source : (H' * W',) int64 — the full map's flat
    pixel under each rebuilt-map pixel, -1 where not counted. covered : (H * W,) bool — full-map
    pixels inside the kept taxels' triangles. full_coverage : (H * W,) bool — the full map's.
    """

    fraction: float
    keep: np.ndarray
    tmap: TactileMap
    source: np.ndarray
    covered: np.ndarray
    full_coverage: np.ndarray


def rebuild(full: TactileMap, layout: TaxelLayout, keep: np.ndarray, fraction: float) -> RemovedMap:
    """The RemovedMap of ``keep`` (the full map itself when every taxel is kept)."""
    keep = np.asarray(keep, dtype=np.int64)
    if len(keep) == full.n_taxels:
        cov = full.coverage().ravel()
        return RemovedMap(fraction, keep, full, np.where(cov, np.arange(cov.size), -1), cov, cov)
    tmap = TactileMap.build(layout.subset(keep), step_mm=full.step_mm)
    corners = keep[tmap.vertex_taxel[tmap.faces]]  # (M, 3) taxels of the full layout
    good = _same_shape(full.uv[corners], tmap.vertex_uv_mm[tmap.faces])
    source = _trace_back(full, tmap, corners, good)
    pix = raster.locate_pixels(
        np.nan_to_num(full.uv), corners[good], full.origin_mm, full.shape, full.step_mm
    )[0]
    covered = np.zeros(full.shape[0] * full.shape[1], dtype=bool)
    covered[pix] = True
    full_cov = full.coverage().ravel()
    return RemovedMap(fraction, keep, tmap, source, covered & full_cov, full_cov)


def _area(tri_uv: np.ndarray) -> np.ndarray:
    """Signed areas (M,) of triangles (M, 3, 2)."""
    e1, e2 = tri_uv[:, 1] - tri_uv[:, 0], tri_uv[:, 2] - tri_uv[:, 0]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def _same_shape(full_uv: np.ndarray, new_uv: np.ndarray) -> np.ndarray:
    """(M,) bool: triangles whose full-map area is within SEAM_AREA_RATIO of the rebuilt one."""
    a_full, a_new = np.abs(_area(full_uv)), np.abs(_area(new_uv))
    ok = np.isfinite(a_full) & (a_new > 0)
    ratio = np.where(ok, a_full / np.where(ok, a_new, 1.0), np.inf)
    return ok & (ratio < SEAM_AREA_RATIO) & (ratio > 1.0 / SEAM_AREA_RATIO)


def _trace_back(full: TactileMap, tmap: TactileMap, corners: np.ndarray, good: np.ndarray):
    """Full-map flat pixel under each rebuilt-map pixel centre (-1: not counted)."""
    pix, face, w = raster.locate_pixels(
        tmap.vertex_uv_mm, tmap.faces, tmap.origin_mm, tmap.shape, tmap.step_mm
    )
    uv = np.einsum("pk,pkd->pd", w, np.nan_to_num(full.uv[corners[face]]))
    col = np.floor((uv[:, 0] - full.origin_mm[0]) / full.step_mm).astype(np.int64)
    row = np.floor((full.origin_mm[1] - uv[:, 1]) / full.step_mm).astype(np.int64)
    h, w_px = full.shape
    ok = good[face] & (row >= 0) & (row < h) & (col >= 0) & (col < w_px)
    flat = np.where(ok, row * w_px + col, 0)
    ok &= full.coverage().ravel()[flat]
    source = np.full(tmap.shape[0] * tmap.shape[1], -1, dtype=np.int64)
    source[pix[ok]] = flat[ok]
    return source


def warp_labels(labels: np.ndarray, removed: RemovedMap, fill: int = IGNORE) -> np.ndarray:
    """Full-map label images (B, H, W) onto the rebuilt map: (B, H', W') uint8, ``fill`` where
    not counted."""
    flat = labels.reshape(len(labels), removed.full_coverage.size)  # (B, H * W)
    out = np.full((len(labels), removed.source.size), fill, dtype=np.uint8)
    valid = removed.source >= 0
    out[:, valid] = flat[:, removed.source[valid]]
    return out.reshape(len(labels), *removed.tmap.shape)


def discarded_hand_pixels(labels: np.ndarray, removed: RemovedMap) -> tuple[int, int]:
    """(hand pixels no longer covered, hand pixels inside the full map's mesh) of full-map
    label images (B, H, W); pixels of the image's dilation rim outside the mesh count in
    neither."""
    hand = (labels.reshape(len(labels), removed.full_coverage.size) > 0) & removed.full_coverage
    return int((hand & ~removed.covered).sum()), int(hand.sum())
