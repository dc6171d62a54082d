"""Fast disk erosion/dilation against skimage.morphology (the reference), borders included."""

from __future__ import annotations

import numpy as np
import pytest
from skimage.morphology import dilation, disk, erosion

from tactile.errors import MapError
from tactile.images import morphology

SHAPES = [(1, 1), (1, 9), (3, 3), (5, 7), (9, 2), (40, 33)]


@pytest.mark.parametrize("radius", range(8))
def test_row_half_widths_make_the_disk(radius: int) -> None:
    rows = np.zeros((2 * radius + 1,) * 2, dtype=bool)
    for dy, half in enumerate(morphology.disk_half_widths(radius)):
        rows[dy, radius - half : radius + half + 1] = True
    np.testing.assert_array_equal(rows, disk(radius).astype(bool))


@pytest.mark.parametrize("radius", range(7))
@pytest.mark.parametrize("shape", SHAPES)
def test_uint8_equals_skimage_incl_borders(radius: int, shape: tuple[int, int]) -> None:
    img = np.random.default_rng(radius).integers(0, 256, shape).astype(np.uint8)
    np.testing.assert_array_equal(morphology.erode(img, radius), erosion(img, disk(radius)))
    np.testing.assert_array_equal(morphology.dilate(img, radius), dilation(img, disk(radius)))


def test_structured_image_equals_skimage() -> None:
    """Bright blobs touching the borders (where the reflect convention matters)."""
    img = np.zeros((30, 45), dtype=np.uint8)
    img[:6, :5] = 200
    img[10:20, 40:] = 120
    img[25:, 20:23] = 255
    img[15, 15] = 90
    for r in (1, 2, 4):
        np.testing.assert_array_equal(morphology.erode(img, r), erosion(img, disk(r)))
        np.testing.assert_array_equal(morphology.dilate(img, r), dilation(img, disk(r)))


def test_batched_equals_per_image() -> None:
    batch = np.random.default_rng(1).integers(0, 256, (4, 23, 31)).astype(np.uint8)
    out = morphology.erode_dilate(batch, 2, 4)
    ref = np.stack([dilation(erosion(im, disk(2)), disk(4)) for im in batch])
    np.testing.assert_array_equal(out, ref)
    assert out.dtype == np.uint8 and out.shape == batch.shape


def test_float_images_and_non_contiguous_input() -> None:
    img = np.random.default_rng(2).random((19, 27))
    np.testing.assert_array_equal(morphology.dilate(img, 3), dilation(img, disk(3)))
    view = img.T  # strided input
    np.testing.assert_array_equal(morphology.erode(view, 2), erosion(view, disk(2)))


def test_zero_radius_is_identity_copy() -> None:
    img = np.arange(12, dtype=np.uint8).reshape(3, 4)
    out = morphology.erode_dilate(img, 0, 0)
    np.testing.assert_array_equal(out, img)
    assert out is not img


@pytest.mark.parametrize("bad", [-1, 1.5])
def test_bad_radius_raises(bad: float) -> None:
    with pytest.raises(MapError, match="radius"):
        morphology.erode(np.zeros((4, 4)), bad)


def test_bad_ndim_raises() -> None:
    with pytest.raises(MapError, match=r"\(H, W\)"):
        morphology.dilate(np.zeros(4), 1)
