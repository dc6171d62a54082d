"""Fast grey erosion and dilation with disk footprints, on single images or batches.

A disk is the union of its rows: row ``dy`` spans the columns ``|dx| <= w(dy)``. The minimum over
the disk is therefore the minimum over ``dy`` of the image's horizontal running minima of half
width ``w(dy)``, shifted by ``dy`` rows; the running minima of half widths 1, 2, ..., r are
built one from the other. That is 4 r array operations for a disk of radius r. The result
equals ``skimage.morphology.erosion`` / ``dilation`` with ``skimage.morphology.disk(radius)``
exactly, borders included: skimage's default ``mode="reflect"`` is scipy.ndimage's
``"reflect"`` (d c b a | a b c d), numpy's ``"symmetric"`` padding.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from skimage.morphology import disk

from tactile.errors import MapError


@lru_cache(maxsize=32)
def disk_half_widths(radius: int) -> tuple[int, ...]:
    """Half width of every row of ``skimage.morphology.disk(radius)``, rows dy = -r..r, pixels:
    row dy holds the columns |dx| <= w(dy)."""
    fp = disk(radius).astype(bool)
    return tuple(int(row.sum()) // 2 for row in fp)


def _check(images: np.ndarray, radius: int) -> None:
    if images.ndim not in (2, 3):
        raise MapError(f"images must be (H, W) or (B, H, W), got shape {images.shape}")
    if int(radius) != radius or radius < 0:
        raise MapError(f"disk radius must be a non-negative integer of pixels, got {radius!r}")


def _disk_filter(images: np.ndarray, radius: int, combine: np.ufunc) -> np.ndarray:
    """Min (or max) of ``images`` over a disk: row-shifted horizontal running minima (maxima)."""
    _check(images, radius)
    if radius == 0:
        return images.copy()
    r, (h, w) = int(radius), images.shape[-2:]
    pad = [(0, 0)] * (images.ndim - 2) + [(r, r), (r, r)]
    padded = np.pad(images, pad, mode="symmetric")  # = scipy.ndimage / skimage "reflect"
    running = [padded[..., r : r + w]]  # running[k]: half width k, all padded rows
    for k in range(1, r + 1):
        step = combine(padded[..., r - k : r - k + w], padded[..., r + k : r + k + w])
        running.append(combine(running[-1], step, out=step))
    out = None
    for dy, half in enumerate(disk_half_widths(r)):
        rows = running[half][..., dy : dy + h, :]
        out = np.array(rows) if out is None else combine(out, rows, out=out)
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
