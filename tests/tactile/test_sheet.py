"""Contact sheets render the right number of tiles, with the label colours where labelled."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from matplotlib.image import imread

from tactile.errors import MapError
from tactile.figures.sheet import overlay, save_contact_sheet
from tactile.images.labels import PALETTE


def test_overlay_colours_labelled_pixels_and_keeps_grey_elsewhere():
    image = np.full((4, 4), 255, np.uint8)
    labels = np.zeros((4, 4), np.uint8)
    labels[0, 0] = 6
    out = overlay(image, labels)
    assert tuple(out[0, 0]) == tuple(PALETTE[6])  # full intensity: the class colour itself
    assert tuple(out[1, 1]) == (255, 255, 255)


def test_sheet_is_a_non_blank_png(tmp_path: Path):
    rng = np.random.default_rng(0)
    images = rng.integers(0, 256, (5, 20, 30), dtype=np.uint8)
    labels = rng.integers(0, 7, (5, 20, 30), dtype=np.uint8)
    path = save_contact_sheet(tmp_path / "s.png", images, labels=labels, titles=list("abcde"))
    pixels = imread(path)
    assert pixels.shape[0] > 100 and pixels.shape[1] > 300
    assert pixels[..., :3].std() > 0.05  # not blank


def test_sheet_rejects_mismatched_titles():
    with pytest.raises(MapError, match="one title per image"):
        save_contact_sheet("unused.png", np.zeros((2, 4, 4), np.uint8), titles=["a"])
