"""Figures from arrays render headless (Agg), at the expected size, and are not blank."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from tactile.errors import MapError
from tactile.figures.panels import (
    error_picture,
    figure_to_array,
    part_bars_figure,
    prediction_figure,
    sample_panel,
    save_sequence_gif,
    sequence_strip,
    trim_background,
)
from tactile.geometry.synthetic import cylinder_sector_layout
from tactile.images.tactile_map import TactileMap


def assert_not_blank(rgb: np.ndarray, min_fraction: float = 0.02) -> None:
    """Pixels vary and a fair share differs from the background (the corner pixel)."""
    assert rgb.ndim == 3 and rgb.shape[2] == 3 and rgb.dtype == np.uint8
    assert rgb.std() > 10
    assert np.mean(np.any(rgb != rgb[0, 0], axis=-1)) > min_fraction


@pytest.fixture(scope="module")
def small_map() -> TactileMap:
    layout, _ = cylinder_sector_layout(width_mm=60.0, length_mm=90.0, n_taxels=80)
    return TactileMap.build(layout, step_mm=2.0)


@pytest.fixture(scope="module")
def blob(small_map: TactileMap) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(pressure (N,) Pa, taxel labels (N,), image (H, W), label image (H, W)) of a fake touch."""
    uv = small_map.uv
    centre = np.nanmean(uv, axis=0)
    d = np.linalg.norm(uv - centre, axis=1)
    pressure = np.clip(20e3 * (1 - d / 25.0), 0, None)
    labels = np.where(pressure > 0, np.where(uv[:, 0] > centre[0], 2, 6), 0)
    image = small_map.image(pressure)
    return pressure, labels, image, small_map.label_image(pressure, labels)


def test_sample_panel_has_its_size_and_content(small_map, blob):
    pressure, _, image, label_image = blob
    view = np.full((120, 300, 3), 255, np.uint8)
    view[30:90, 50:250] = (200, 120, 90)
    fig = sample_panel(view, small_map, image, label_image, pressure, title="t")
    rgb = figure_to_array(fig, dpi=50)
    width, height = fig.get_size_inches() * 50
    assert abs(rgb.shape[0] - height) <= 1 and abs(rgb.shape[1] - width) <= 1
    assert_not_blank(rgb, 0.1)


def test_sample_panel_rejects_an_image_of_another_map(small_map):
    with pytest.raises(MapError, match="differs from the map"):
        sample_panel(None, small_map, np.zeros((3, 3), np.uint8))


def test_trim_background_keeps_the_content_with_a_margin():
    rgb = np.full((50, 80, 3), 255, np.uint8)
    rgb[10:20, 30:40] = 0
    assert trim_background(rgb, pad_px=2).shape == (14, 14, 3)


def test_sequence_strip_and_gif(tmp_path: Path, blob):
    image = blob[2]
    seq = np.stack([(image * f).astype(np.uint8) for f in (0.0, 0.5, 1.0, 0.7)])
    rgb = figure_to_array(sequence_strip(seq, title="press"), dpi=50)
    assert_not_blank(rgb, 0.1)
    path = save_sequence_gif(tmp_path / "s.gif", seq, scale=2)
    gif = Image.open(path)
    assert gif.n_frames == 4 and gif.size == (2 * image.shape[1], 2 * image.shape[0])
    gif.seek(2)
    assert np.asarray(gif.convert("RGB")).std() > 10


def test_error_picture_marks_only_wrong_pixels_red():
    image = np.full((3, 3), 100, np.uint8)
    true = np.zeros((3, 3), int)
    pred = true.copy()
    pred[1, 1] = 2
    out = error_picture(image, true, pred)
    assert tuple(out[1, 1]) == (255, 0, 0) and tuple(out[0, 0]) == (100, 100, 100)


def test_prediction_figure_reports_accuracy(blob):
    _, _, image, label_image = blob
    pred = label_image.copy()
    pred[pred == 2] = 3  # index read as middle
    fig = prediction_figure(image, label_image, pred, title="ablated")
    assert "accuracy" in fig.axes[3].get_title()
    rgb = figure_to_array(fig, dpi=50)
    width, height = fig.get_size_inches() * 50
    assert abs(rgb.shape[0] - height) <= 1 and abs(rgb.shape[1] - width) <= 1
    assert_not_blank(rgb, 0.1)
    red = np.all(rgb == (255, 0, 0), axis=-1)
    assert red.any()


def test_part_bars_show_true_and_predicted(blob):
    pressure, labels, _, _ = blob
    pred = np.where(labels == 2, 3, labels)
    fig = part_bars_figure(labels, pressure, pred_labels=pred)
    heights = [p.get_height() for p in fig.axes[1].patches]
    assert len(heights) == 12 and sum(heights) == 2 * np.count_nonzero(pressure)
    assert_not_blank(figure_to_array(fig, dpi=50), 0.05)


def test_prediction_figure_without_ground_truth(blob):
    _, _, image, label_image = blob
    fig = prediction_figure(image, None, label_image, pred_name="model")
    assert [ax.get_title() for ax in fig.axes] == ["tactile image", "model"]
    rgb = figure_to_array(fig, dpi=50)
    width, height = fig.get_size_inches() * 50
    assert abs(width - 50 * 13 / 2) <= 1
    assert abs(rgb.shape[0] - height) <= 1 and abs(rgb.shape[1] - width) <= 1
    assert_not_blank(rgb, 0.1)
    assert not np.all(rgb == (255, 0, 0), axis=-1).any()  # no error panel
    with pytest.raises(MapError, match="differ"):
        prediction_figure(image, None, label_image[:-1])


def test_part_bars_of_a_prediction_alone(blob):
    pressure, labels, _, _ = blob
    fig = part_bars_figure(None, pressure, pred_labels=labels)
    counts = [p.get_height() for p in fig.axes[1].patches]
    assert counts == [np.count_nonzero((labels == c) & (pressure > 0)) for c in range(1, 7)]
    kpa = [p.get_height() for p in fig.axes[0].patches]
    assert kpa[1] == pytest.approx(pressure[labels == 2].mean() / 1e3)
    assert all(p.get_hatch() == "//" for p in fig.axes[1].patches)
    assert_not_blank(figure_to_array(fig, dpi=50), 0.05)
    with pytest.raises(MapError, match="true labels, predicted labels or both"):
        part_bars_figure(None, pressure)
