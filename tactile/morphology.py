"""Fast grey erosion and dilation with disk footprints, on single images or batches.

A disk is a union of centred rectangles (one per distinct row half-width), a grey erosion by a
union is the minimum of the erosions by its parts, and an erosion by a rectangle is separable
into two 1-D minimum filters. The result equals ``skimage.morphology.erosion`` / ``dilation``
with ``skimage.morphology.disk(radius)`` exactly, borders included: skimage's default
``mode="reflect"`` is scipy.ndimage's ``"reflect"`` (d c b a | a b c d), which is separable.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import lru_cache

import numpy as np
from skimage.morphology import disk

from tactile.errors import MapError

Filter1d = Callable[..., np.ndarray]


@lru_cache(maxsize=32)
def disk_rectangles(radius: int) -> tuple[tuple[int, int], ...]:
    """Centred rectangles whose union is ``skimage.morphology.disk(radius)``.

    Returns
    -------
    rects : tuple of (half_height, half_width) in pixels — rectangle rows |dy| <= half_height,
        columns |dx| <= half_width; one per distinct row half-width, widest first.
    """
    fp = disk(radius).astype(bool)
    half_widths = fp.sum(axis=1)[radius:] // 2  # rows dy = 0..radius, centred odd runs
    rects = []
    for w in np.unique(half_widths)[::-1]:
        rects.append((int(np.flatnonzero(half_widths == w).max()), int(w)))
    return tuple(rects)


def _check(images: np.ndarray, radius: int) -> None:
    if images.ndim not in (2, 3):
        raise MapError(f"images must be (H, W) or (B, H, W), got shape {images.shape}")
    if int(radius) != radius or radius < 0:
        raise MapError(f"disk radius must be a non-negative integer of pixels, got {radius!r}")


def _window(x: np.ndarray, n: int, axis: int, combine: np.ufunc) -> np.ndarray:
    """Min (max) over every run of ``n`` along ``axis``: length L -> L - n + 1 (sparse table)."""
    length = x.shape[axis]
    acc, span = x, 1  # acc[i] = min(x[i : i + span]), length - span + 1 entries
    while 2 * span <= n:
        m = length - 2 * span + 1
        acc = combine(_take(acc, 0, m, axis), _take(acc, span, span + m, axis))
        span *= 2
    if span == n:
        return acc
    m = length - n + 1
    return combine(_take(acc, 0, m, axis), _take(acc, n - span, n - span + m, axis))


def _take(x: np.ndarray, start: int, stop: int | None, axis: int) -> np.ndarray:
    index = [slice(None)] * x.ndim
    index[axis] = slice(start, stop)
    return x[tuple(index)]


def _disk_filter(images: np.ndarray, radius: int, combine: np.ufunc) -> np.ndarray:
    """Min (or max) of ``images`` over a disk, via its rectangles and separable 1-D windows."""
    _check(images, radius)
    if radius == 0:
        return images.copy()
    r, (h, w) = int(radius), images.shape[-2:]
    pad = [(0, 0)] * (images.ndim - 2) + [(r, r), (r, r)]
    padded = np.pad(images, pad, mode="symmetric")  # = scipy.ndimage / skimage "reflect"
    out = None
    for half_h, half_w in disk_rectangles(r):
        rows = padded[..., r - half_h : r + half_h + h, :]
        rect = _window(rows, 2 * half_w + 1, -1, combine)[..., r - half_w : r - half_w + w]
        rect = _window(rect, 2 * half_h + 1, -2, combine)
        out = np.array(rect) if out is None else combine(out, rect, out=out)
    return out


def erode(images: np.ndarray, radius: int) -> np.ndarray:
    """Grey erosion by ``disk(radius)``, = ``skimage.morphology.erosion`` per image.

    Parameters
    ----------
    images : (H, W) or (B, H, W) array (any real dtype; kept).
    radius : int, pixels; 0 returns a copy.

    Returns
    -------
    eroded : same shape and dtype.
    """
    return _disk_filter(images, radius, np.minimum)


def dilate(images: np.ndarray, radius: int) -> np.ndarray:
    """Grey dilation by ``disk(radius)``, = ``skimage.morphology.dilation`` per image.

    Parameters
    ----------
    images : (H, W) or (B, H, W) array (any real dtype; kept).
    radius : int, pixels; 0 returns a copy.

    Returns
    -------
    dilated : same shape and dtype.
    """
    return _disk_filter(images, radius, np.maximum)


def erode_dilate(images: np.ndarray, erode_px: int, dilate_px: int) -> np.ndarray:
    """Erosion by ``disk(erode_px)`` then dilation by ``disk(dilate_px)`` (the paper's clean-up).

    Parameters
    ----------
    images : (H, W) or (B, H, W) array. erode_px, dilate_px : int, pixels; 0 skips that step.

    Returns
    -------
    cleaned : same shape and dtype.
    """
    return dilate(erode(images, erode_px), dilate_px)
