"""Hand-part classes on the tactile map: per-pixel label images, back-projection, part summaries.

Classes follow Albini & Cannata (IJRR 2020): background, the five fingers and the palm. A label
image is consistent with the tactile image: a pixel is labelled where the tactile image is
non-zero, with the class whose own (interpolated, dilated) pressure field is largest there.

The functions take a `tactile.images.tactile_map.TactileMap` as ``tmap``; the map's own
``label_image`` method calls them, so this module sits below it and does not import it.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from tactile.errors import MapError
from tactile.images.morphology import dilate

CLASS_NAMES = ("background", "thumb", "index", "middle", "ring", "pinkie", "palm")
# RGB per class, after the paper's Fig. 10 (one distinct hue per part; background black).
PALETTE = np.array(
    [
        [0, 0, 0],  # background
        [230, 25, 75],  # thumb: red
        [255, 225, 25],  # index: yellow
        [60, 180, 75],  # middle: green
        [0, 130, 200],  # ring: blue
        [245, 130, 48],  # pinkie: orange
        [145, 30, 180],  # palm: purple
    ],
    dtype=np.uint8,
)
N_CLASSES = len(CLASS_NAMES)
#: The label of a pixel no loss or score counts (a pressed pixel that no box names, in
#: box-derived labels; a pixel a map rebuilt without some taxels cannot place).
IGNORE = 255


class PartSummary(NamedTuple):
    """Activity of one hand part: taxels pressed and their mean pressure (0 when none)."""

    n_taxels: int
    mean_pressure: float


def check_labels(labels: np.ndarray, n_taxels: int, n_classes: int = N_CLASSES) -> np.ndarray:
    """Validate per-taxel class ids: (N,) int in 0..n_classes-1. Returns them as int64."""
    lab = np.asarray(labels)
    if lab.shape != (n_taxels,) or (lab.size and not np.issubdtype(lab.dtype, np.integer)):
        raise MapError(
            f"labels must be ({n_taxels},) integer class ids, got shape {lab.shape}, {lab.dtype}"
        )
    if lab.size and (lab.min() < 0 or lab.max() >= n_classes):
        raise MapError(
            f"labels must lie in 0..{n_classes - 1} ({', '.join(CLASS_NAMES)}), "
            f"got {lab.min()}..{lab.max()}"
        )
    return lab.astype(np.int64)


def label_image(
    tmap,
    p: np.ndarray,
    labels: np.ndarray,
    *,
    erode_px: int = 2,
    dilate_px: int = 4,
    image: np.ndarray | None = None,
) -> np.ndarray:
    """Per-pixel class, consistent with ``tmap.image(p)``.

    Each class c gets its own pressure field ``p * (labels == c)``, interpolated on the map and
    grey-dilated by ``disk(dilate_px)`` like the image (so every foreground pixel of the image
    sees a positive field); a pixel takes the class of the largest field where the tactile image
    is non-zero (the lowest class of fields within 8 ulps of each other), background (0)
    elsewhere. Pressure on class-0 taxels labels its pixels 0.

    Parameters
    ----------
    tmap : TactileMap. p : (N,) float pressures (>= 0). labels : (N,) int, 0..6.
    erode_px, dilate_px : int, pixels — the image's morphology.
    image : (H, W) uint8, optional — ``tmap.image(p, erode_px=..., dilate_px=...)`` when the
        caller already has it (it is not recomputed; passing another image is the caller's bug).

    Returns
    -------
    classes : (H, W) uint8, 0..6 (all 0 without a labelled taxel; the image is then not needed).
    """
    lab = check_labels(labels, tmap.n_taxels)
    p = np.asarray(p)
    if p.ndim != 1:
        raise MapError(f"label_image takes one frame p of shape ({tmap.n_taxels},), got {p.shape}")
    if image is not None and np.shape(image) != tmap.shape:
        raise MapError(f"image must have the map's shape {tmap.shape}, got {np.shape(image)}")
    if not lab.any():
        return np.zeros(tmap.shape, dtype=np.uint8)
    if image is None:
        image = tmap.image(p, erode_px=erode_px, dilate_px=dilate_px)
    foreground = np.asarray(image) > 0
    out = np.zeros(tmap.shape, dtype=np.uint8)
    if not foreground.any():
        return out
    # Only the classes present (background always, so ties resolve as over all 7 classes), and
    # only the foreground's box grown by the dilation radius: the same result, a fraction of
    # the work.
    classes = np.union1d([0], lab[p > 0])
    fields = np.where(lab[None, :] == classes[:, None], p[None, :], 0.0)
    rows, cols = _grown_box(foreground, dilate_px)
    interpolated = tmap.interpolate_box(fields, rows, cols)
    spread = dilate(_class_keys(interpolated), dilate_px)
    winner = classes[_KEY_CLASSES - (spread & _KEY_CLASSES)]
    out[rows, cols] = np.where(foreground[rows, cols], winner, 0)
    return out


_KEY_CLASSES = 7  # the low three bits of a key: 7 - the class's index among those present


def _class_keys(fields: np.ndarray) -> np.ndarray:
    """(C, h, w) non-negative fields -> (h, w) int64 keys whose order is (largest field, then the
    first class): the field's float64 bits (ordered as the value for values >= 0) with the low
    three bits replaced by 7 - the class's index. The largest key over a disk is therefore the
    class of the largest dilated field, lowest class on ties, as argmax over the dilated fields
    (C dilations) gives it, in one dilation; fields within 8 ulps count as tied."""
    fields = np.ascontiguousarray(fields)  # one plane per class: 4x faster than strided argmax
    best = fields.max(axis=0)
    first = np.zeros(best.shape, dtype=np.int64)  # the first class reaching the maximum
    for c in range(len(fields) - 1, -1, -1):
        first[fields[c] == best] = c
    return (best.view(np.int64) & ~_KEY_CLASSES) | (_KEY_CLASSES - first)


def _grown_box(mask: np.ndarray, margin_px: int) -> tuple[slice, slice]:
    """Row and column slices of the bounding box of ``mask`` (H, W) grown by ``margin_px``."""
    r = np.flatnonzero(mask.any(axis=1))
    c = np.flatnonzero(mask.any(axis=0))
    h, w = mask.shape
    return (
        slice(max(r[0] - margin_px, 0), min(r[-1] + margin_px + 1, h)),
        slice(max(c[0] - margin_px, 0), min(c[-1] + margin_px + 1, w)),
    )


def colorize(classes: np.ndarray) -> np.ndarray:
    """RGB picture of a label image: (..., H, W) int 0..6 -> (..., H, W, 3) uint8 via PALETTE."""
    return PALETTE[np.asarray(classes)]


def neighbourhood_matrix(tmap, radius_mm: float) -> sp.csr_matrix:
    """(N, H * W) 0/1 CSR: pixels whose centre lies within ``radius_mm`` of any of a taxel's
    vertices on the map (a taxel on a seam has several)."""
    (height, width), step = tmap.shape, tmap.step_mm
    reach = int(np.ceil(radius_mm / step)) + 1
    dr, dc = np.mgrid[-reach : reach + 1, -reach : reach + 1].reshape(2, -1)
    col0 = np.floor((tmap.vertex_uv_mm[:, 0] - tmap.origin_mm[0]) / step).astype(np.int64)
    row0 = np.floor((tmap.origin_mm[1] - tmap.vertex_uv_mm[:, 1]) / step).astype(np.int64)
    rows, cols = row0[:, None] + dr, col0[:, None] + dc  # (V, K) candidate pixels
    du = tmap.origin_mm[0] + (cols + 0.5) * step - tmap.vertex_uv_mm[:, :1]
    dv = tmap.origin_mm[1] - (rows + 0.5) * step - tmap.vertex_uv_mm[:, 1:]
    inside = (du**2 + dv**2 <= radius_mm**2) & (rows >= 0) & (rows < height)
    inside &= (cols >= 0) & (cols < width)
    vertex, _ = np.nonzero(inside)
    pixel = rows[inside] * width + cols[inside]
    ones = np.ones(len(pixel))
    shape = (tmap.n_taxels, height * width)
    matrix = sp.csr_matrix((ones, (tmap.vertex_taxel[vertex], pixel)), shape=shape)
    matrix.sum_duplicates()
    matrix.data[:] = 1.0
    return matrix


def backproject(tmap, seg: np.ndarray, *, radius_mm: float | None = None) -> np.ndarray:
    """Per-taxel labels from a per-pixel segmentation.

    Each taxel takes the most frequent non-background class among the pixels within
    ``radius_mm`` of it on the map (ties: the smaller class id), background (0) where none.

    Parameters
    ----------
    tmap : TactileMap. seg : (H, W) or (B, H, W) int classes 0..6 (e.g. a network's output).
    radius_mm : float, mm; default 2 pixels (2 * step_mm).

    Returns
    -------
    labels : (N,) or (B, N) uint8.
    """
    seg = np.asarray(seg)
    if seg.shape[-2:] != tmap.shape or seg.ndim not in (2, 3):
        raise MapError(f"seg must be (H, W) or (B, H, W), (H, W) = {tmap.shape}; got {seg.shape}")
    radius = 2.0 * tmap.step_mm if radius_mm is None else float(radius_mm)
    near = neighbourhood_matrix(tmap, radius)
    flat = seg.reshape(-1, tmap.shape[0] * tmap.shape[1])
    counts = np.stack([near @ (flat == c).T.astype(np.float64) for c in range(1, N_CLASSES)])
    best = counts.argmax(axis=0) + 1  # (N, B)
    out = np.where(counts.max(axis=0) > 0, best, 0).T.astype(np.uint8)
    return out[0] if seg.ndim == 2 else out


# m: pressed taxels closer than this belong to one contact: a hand's fingers and palm stay one
# (on two-contact forearm samples, 50 mm separated the contacts best)
CONTACT_GAP_M = 0.05
MIN_CONTACT_TAXELS = 3  # taxels: a smaller group of pressed taxels is read noise


def contact_instances(
    positions_m: np.ndarray,
    p: np.ndarray,
    *,
    threshold: float = 0.0,
    gap_m: float = CONTACT_GAP_M,
    min_taxels: int = MIN_CONTACT_TAXELS,
) -> np.ndarray:
    """Which contact each pressed taxel belongs to: the groups of taxels above ``threshold``
    linked by chains of taxels less than ``gap_m`` apart on the skin (3D, so a seam of the map
    splits nothing). A hand's fingers and palm lie within a finger's gap of each other; two
    hands or a hand and an object pressing apart are two contacts.

    Parameters
    ----------
    positions_m : (N, 3) float, m. p : (N,) float pressures. threshold : same unit as p.
    gap_m : float, m. min_taxels : groups of fewer pressed taxels are read noise, not a contact.

    Returns
    -------
    instances : (N,) int64 — 0 for a taxel not pressed (or in a group under ``min_taxels``),
        else 1..K, contact 1 with the largest summed pressure.
    """
    from scipy.sparse.csgraph import connected_components  # start-up: scipy.sparse.csgraph
    from scipy.spatial import cKDTree  # start-up: scipy.spatial

    p = np.asarray(p, dtype=np.float64)
    pressed = np.flatnonzero(p > threshold)
    out = np.zeros(len(p), np.int64)
    if not pressed.size:
        return out
    pairs = cKDTree(np.asarray(positions_m)[pressed]).query_pairs(gap_m, output_type="ndarray")
    graph = sp.coo_matrix(
        (np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(pressed.size,) * 2
    )
    _, group = connected_components(graph, directed=False)
    load = np.bincount(group, weights=p[pressed])
    load[np.bincount(group) < min_taxels] = -1.0  # noise: dropped below
    rank = np.zeros(len(load), dtype=np.int64)
    kept = np.argsort(-load, kind="stable")[: int((load >= 0).sum())]
    rank[kept] = np.arange(1, len(kept) + 1)
    out[pressed] = rank[group]
    return out


def part_summary(
    labels: np.ndarray, p: np.ndarray, *, threshold: float = 0.0
) -> dict[str, PartSummary]:
    """Per hand part: number of pressed taxels (label c and p > threshold) and their mean pressure.

    Parameters
    ----------
    labels : (N,) int classes 0..6. p : (N,) float pressures. threshold : same unit as p.

    Returns
    -------
    summary : {part name: PartSummary(n_taxels, mean_pressure)} for the six parts (no background).
    """
    p = np.asarray(p, dtype=np.float64)
    lab = check_labels(labels, len(p))
    out = {}
    for c, name in enumerate(CLASS_NAMES[1:], start=1):
        pressed = p[(lab == c) & (p > threshold)]
        out[name] = PartSummary(len(pressed), float(pressed.mean()) if len(pressed) else 0.0)
    return out
