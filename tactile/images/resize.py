"""Resizing tactile images and label images to a network's input size (the paper uses 68 × 100).

Images are resized with anti-aliasing (Gaussian pre-filter, bilinear), keeping their dtype
semantics: uint8 stays uint8 in 0..255 (rounded), floats keep their dtype and range. Label
images use nearest neighbour so that no class is invented at boundaries.

A label image is non-zero exactly where its tactile image is (`tactile.images.labels`). The blur of
an anti-aliased resize widens an image's non-zero support (by ~1.7× in area on the forearm map
at 68 × 100), while the nearest-neighbour labels keep theirs, so a segmenter would be asked to
call background what it sees pressed. ``keep_support=True`` keeps the two consistent: the
resized image is non-zero exactly where the nearest-neighbour resize of ``img > 0`` is.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from skimage.transform import resize

from tactile.errors import ConfigError

NET_SIZE = (68, 100)  # (H, W) pixels, the paper's network input

#: The weights of `resize_operator` are multiples of 2**-WEIGHT_BITS (see `resize_grey`).
WEIGHT_BITS = 20


def _check(img: np.ndarray, size: tuple[int, int]) -> tuple[int, int]:
    if img.ndim not in (2, 3):
        raise ConfigError(f"expected an (H, W) or (B, H, W) image, got shape {img.shape}")
    h, w = (int(s) for s in size)
    if h < 1 or w < 1:
        raise ConfigError(f"size must be (H, W) with positive pixels, got {size!r}")
    return h, w


def _resize_one(img: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    out = resize(img.astype(np.float64), size, order=1, anti_aliasing=True, preserve_range=True)
    if img.dtype == np.uint8:
        return np.clip(np.rint(out), 0, 255).astype(np.uint8)
    if np.issubdtype(img.dtype, np.integer):
        info = np.iinfo(img.dtype)
        return np.clip(np.rint(out), info.min, info.max).astype(img.dtype)
    return out.astype(img.dtype)


def _resize_on_support(img: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    """`_resize_one`, zero outside the nearest-neighbour support of ``img > 0`` and at least
    the frame's smallest positive value inside it."""
    out = _resize_one(img, size)
    pressed = img > 0
    if not pressed.any():
        return out
    support = resize_labels(pressed, size)
    return np.where(support, np.maximum(out, img[pressed].min()), 0).astype(img.dtype)


def resize_image(
    img: np.ndarray, size: tuple[int, int] = NET_SIZE, *, keep_support: bool = False
) -> np.ndarray:
    """Anti-aliased resize of a tactile image or a batch of them.

    Parameters
    ----------
    img : (H, W) or (B, H, W), uint8 (0..255) or float (>= 0 for ``keep_support``).
    size : (h, w) pixels.
    keep_support : zero the output outside ``resize_labels(img > 0, size)`` and keep it
        positive inside (at least the image's smallest positive value), so that it is non-zero
        exactly where a label image resized by `resize_labels` is labelled.

    Returns
    -------
    resized : (h, w) or (B, h, w), same dtype (integers rounded and clipped to their range).
    """
    img = np.asarray(img)
    h, w = _check(img, size)
    one = _resize_on_support if keep_support else _resize_one
    if img.ndim == 2:
        return one(img, (h, w))
    return np.stack([one(frame, (h, w)) for frame in img]).reshape(len(img), h, w)


def resize_labels(lbl: np.ndarray, size: tuple[int, int] = NET_SIZE) -> np.ndarray:
    """Nearest-neighbour resize of a label image or a batch of them (no new classes).

    Output pixel (i, j) takes input pixel (floor((i + 0.5) H / h), floor((j + 0.5) W / w)).

    Parameters
    ----------
    lbl : (H, W) or (B, H, W) int. size : (h, w) pixels.

    Returns
    -------
    resized : (h, w) or (B, h, w), same dtype.
    """
    lbl = np.asarray(lbl)
    h, w = _check(lbl, size)
    rows = _nearest(lbl.shape[-2], h)
    cols = _nearest(lbl.shape[-1], w)
    return lbl[..., rows[:, None], cols[None, :]]


def _nearest(n_in: int, n_out: int) -> np.ndarray:
    """Source index of each of ``n_out`` output samples over ``n_in`` inputs (centre rule)."""
    return np.minimum(((np.arange(n_out) + 0.5) * n_in / n_out).astype(np.int64), n_in - 1)


def canvas_px(canvas_mm: tuple[float, float], step_mm: float) -> tuple[int, int]:
    """(H, W) map-grid pixels of a canvas of ``canvas_mm`` (H, W) mm on a grid of ``step_mm``
    mm per pixel (rounded, at least 1)."""
    if step_mm <= 0:
        raise ConfigError(f"grid step must be > 0 mm, got {step_mm}")
    return tuple(max(1, round(float(c) / step_mm)) for c in canvas_mm)


def fit_canvas(img: np.ndarray, canvas: tuple[int, int]) -> np.ndarray:
    """Centre a tactile or label image (or a batch) on a canvas of (H', W') pixels: zero-padded
    where the canvas is larger, centre-cropped where it is smaller, at the same pixel scale.

    With the canvas's size the same on every part, a resize to a network input maps one
    millimetre of every part's map to the same number of input pixels, so a hand's print has
    the same size in pixels on a small part as on a large one. Applied with the image's own
    (H, W), it is its own inverse wherever nothing was cropped: ``fit_canvas(fit_canvas(a, c),
    a.shape[-2:])`` equals ``a`` when the canvas is at least the image's size.

    Parameters
    ----------
    img : (H, W) or (B, H, W), any dtype. canvas : (H', W') pixels.

    Returns
    -------
    (H', W') or (B, H', W'), same dtype; pixel (i, j) of the input lands at
    (i + (H' - H) // 2, j + (W' - W) // 2) when padding, at (i - (H - H') // 2, j - (W - W')
    // 2) when cropping (pixels falling outside are dropped).
    """
    img = np.asarray(img)
    ch, cw = _check(img, canvas)
    out = np.zeros((*img.shape[:-2], ch, cw), dtype=img.dtype)
    src, dst = [], []
    for n_in, n_out in zip(img.shape[-2:], (ch, cw), strict=True):
        # where input index 0 lands: the same split of the margin when padding and cropping
        off = (n_out - n_in) // 2 if n_out >= n_in else -((n_in - n_out) // 2)
        lo, hi = max(0, off), min(n_out, off + n_in)
        dst.append(slice(lo, hi))
        src.append(slice(lo - off, hi - off))
    out[..., dst[0], dst[1]] = img[..., src[0], src[1]]
    return out


@lru_cache(maxsize=64)
def resize_operator(n_in: int, n_out: int) -> np.ndarray:
    """(n_out, n_in) float64, read-only: `resize_image` along one axis as a matrix (the resize
    of the identity: Gaussian pre-filter and bilinear zoom are linear and separable), each
    weight rounded to a multiple of 2**-20 (`WEIGHT_BITS`; at most 4.8e-7 from skimage's)."""
    op = resize_image(np.eye(n_in), (n_out, n_in))
    op = np.ldexp(np.rint(np.ldexp(op, WEIGHT_BITS)), -WEIGHT_BITS)
    op.flags.writeable = False
    return op


def resize_grey(
    grey: np.ndarray, size: tuple[int, int] = NET_SIZE, *, keep_support: bool = False
) -> np.ndarray:
    """A network's view of tactile image(s): the anti-aliased resize of grey levels, / 255.

    Computed as ``rows @ grey @ cols.T / 255`` in float64 with the operators of
    `resize_operator`. Every partial sum of those products is exact: the grey levels are
    integers below 2**8 and the weights multiples of 2**-20 whose rows sum to 1, so every sum is
    a multiple of 2**-40 below 2**8, which float64's 53 bits hold. Any order of summation
    therefore gives the same bytes: any BLAS, any CPU, any thread count, and the resize of any
    box of the image that holds its non-zero pixels (`learn.infer.frame`). It differs from
    ``resize_image(grey / 255)`` by the weights' rounding: at most 1e-5 (tests).

    Parameters
    ----------
    grey : (H, W) or (B, H, W) uint8 grey levels. size : (h, w) pixels.
    keep_support : as `resize_image`: zero outside ``resize_labels(grey > 0, size)`` and at
        least the image's smallest pressed grey level / 255 inside it.

    Returns
    -------
    (h, w) or (B, h, w) float32 in [0, 1].
    """
    grey = np.asarray(grey)
    if grey.dtype != np.uint8:
        raise ConfigError(f"resize_grey takes uint8 grey levels, got {grey.dtype}")
    h, w = _check(grey, size)
    rows, cols = resize_operator(grey.shape[-2], h), resize_operator(grey.shape[-1], w)
    sums = [rows @ g.astype(np.float64) @ cols.T for g in grey.reshape(-1, *grey.shape[-2:])]
    out = (np.stack(sums).reshape(*grey.shape[:-2], h, w) / 255.0).astype(np.float32)
    if not keep_support:
        return out
    pressed = grey > 0
    support = resize_labels(pressed, (h, w))
    low = np.where(pressed, grey, 255).min(axis=(-2, -1), keepdims=True)
    low = low.astype(np.float32) / np.float32(255.0)
    return np.where(support, np.maximum(out, low), np.float32(0))
