"""`tactile.images.resize.resize_grey`, the network's view of a tactile image, against skimage's
resize (its slow reference, within the stated rounding of the weights) and against exact rational
arithmetic (its sums are exact, so no CPU, BLAS or order of summation can change its bytes)."""

from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from tactile.errors import ConfigError
from tactile.images.resize import (
    WEIGHT_BITS,
    resize_grey,
    resize_image,
    resize_labels,
    resize_operator,
)


def grey_image(shape=(61, 97), seed=0) -> np.ndarray:
    """Seeded (H, W) uint8 with an empty margin, blobs and single pixels, levels 1..255."""
    rng = np.random.default_rng(seed)
    img = np.zeros(shape, np.uint8)
    h, w = shape
    img[h // 6 : h // 2, w // 5 : w // 2] = rng.integers(1, 256, (h // 2 - h // 6, w // 2 - w // 5))
    img[rng.integers(2, h - 2, 15), rng.integers(2, w - 2, 15)] = 255
    return img


@pytest.mark.parametrize("size", [(17, 25), (34, 50), (80, 120)])
def test_resize_grey_is_skimage_within_the_weights_rounding(size):
    img = grey_image()
    ref = resize_image(img.astype(np.float64) / 255.0, size)
    # each weight moves by at most 2**-21; a pixel sums at most (rows' nonzeros x columns')
    # weights, each times at most 1
    rows, cols = resize_operator(img.shape[0], size[0]), resize_operator(img.shape[1], size[1])
    n = (rows != 0).sum(1).max() + (cols != 0).sum(1).max()
    np.testing.assert_allclose(resize_grey(img, size), ref, atol=n * 2.0 ** -(WEIGHT_BITS + 1))


def test_resize_grey_sums_are_exact():
    """The float64 result equals the rational one: every partial sum fits float64's mantissa."""
    img = grey_image((23, 31), seed=3)
    size = (7, 11)
    rows, cols = resize_operator(23, 7), resize_operator(31, 11)
    assert np.array_equal(rows, np.ldexp(np.rint(np.ldexp(rows, WEIGHT_BITS)), -WEIGHT_BITS))
    fr = [[Fraction(float(v)) for v in r] for r in rows]
    fc = [[Fraction(float(v)) for v in r] for r in cols]
    exact = [
        [
            sum(fr[i][a] * int(img[a, b]) * fc[j][b] for a in range(23) for b in range(31))
            for j in range(11)
        ]
        for i in range(7)
    ]
    want = np.array([[np.float32(float(v / 255)) for v in r] for r in exact])
    assert np.array_equal(resize_grey(img, size), want)


def test_resize_grey_on_a_box_and_in_any_order_gives_the_same_bytes():
    img = grey_image()
    size = (34, 50)
    full = resize_grey(img, size)
    rows, cols = resize_operator(61, 34), resize_operator(97, 50)
    (r0, r1), (c0, c1) = ((i.min(), i.max() + 1) for i in np.nonzero(img))
    assert r1 - r0 < img.shape[0] and c1 - c0 < img.shape[1]  # a box inside the image
    box = img[r0:r1, c0:c1].astype(np.float64)
    part = (rows[:, r0:r1] @ box @ cols[:, c0:c1].T / 255.0).astype(np.float32)
    assert np.array_equal(part, full)
    columns_first = (rows @ (img.astype(np.float64) @ cols.T) / 255.0).astype(np.float32)
    assert np.array_equal(columns_first, full)
    reversed_sum = np.zeros(size)
    for a in range(60, -1, -1):  # one row of the image at a time, last to first
        reversed_sum += np.outer(rows[:, a], img[a].astype(np.float64) @ cols.T)
    assert np.array_equal((reversed_sum / 255.0).astype(np.float32), full)


def test_resize_grey_batches_and_keeps_support():
    img = grey_image()
    size = (34, 50)
    batch = resize_grey(np.stack([img, np.zeros_like(img), img[::-1]]), size, keep_support=True)
    assert batch.dtype == np.float32 and batch.shape == (3, *size)
    kept = resize_grey(img, size, keep_support=True)
    assert np.array_equal(batch[0], kept) and not batch[1].any()
    assert np.array_equal(batch[2], resize_grey(img[::-1], size, keep_support=True))
    support = resize_labels(img > 0, size)
    assert np.array_equal(kept > 0, support)
    assert kept[support].min() >= np.float32(img[img > 0].min()) / np.float32(255)


def test_resize_grey_takes_grey_levels_only():
    with pytest.raises(ConfigError, match="resize_grey takes uint8 grey levels, got float32"):
        resize_grey(np.zeros((4, 4), np.float32), (2, 2))
