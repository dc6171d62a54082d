"""Network-input rule: segmentation inputs on their labels' support, and checkpoints that record
the rule (a segmenter trained before it is refused, a classifier is not)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from learn import config as C
from learn.config import RunConfig
from learn.data.load import TensorData
from learn.inputs import INPUTS, net_input, unpressed_as_background
from learn.models import create_model
from learn.train.checkpoint import inputs_stale, make_checkpoint, model_from_checkpoint
from learn.train.validation import evaluate_tensors
from tactile.config import to_dict
from tactile.errors import DataError


def test_net_input_by_task_on_a_closed_form_case():
    """A single lit pixel of an (8, 8) image halved to (4, 4): the blur spreads it over the
        output, the segmentation input keeps only the pixel whose centre-rule source is lit, at no
    less than the image's smallest positive value."""
    img = np.zeros((8, 8), np.uint8)
    img[3, 5] = 255  # output (1, 2) samples source (floor(1.5 * 2), floor(2.5 * 2)) = (3, 5)
    blur = net_input(img, (4, 4), "classify")
    kept = net_input(img, (4, 4), "segment")
    assert (blur > 0).sum() > 1
    want = np.zeros((4, 4), bool)
    want[1, 2] = True
    np.testing.assert_array_equal(kept > 0, want)
    assert blur[1, 2] < 1.0 and kept[1, 2] == 1.0  # raised to the smallest positive input


def _checkpoint(preset, drop_inputs: bool) -> dict:
    run = RunConfig(model=preset.model, train=preset.train)
    model: nn.Module = create_model(run.model.arch, **run.model.kwargs())
    ckpt = make_checkpoint(model, to_dict(run), epoch=1, best_metric=0.5)
    assert ckpt["inputs"] == INPUTS
    if drop_inputs:
        del ckpt["inputs"]
    return ckpt


def test_old_segmenters_are_refused_classifiers_are_not():
    model_from_checkpoint(_checkpoint(C.SEGNET, drop_inputs=False))
    model_from_checkpoint(_checkpoint(C.HANDSNET, drop_inputs=True))
    old = _checkpoint(C.SEGNET, drop_inputs=True)
    assert inputs_stale(old, "segment") and not inputs_stale(old, "classify")
    with pytest.raises(DataError, match=r"labels' support.*Fix: retrain"):
        model_from_checkpoint(_checkpoint(C.SEGNET, drop_inputs=True))


class Constant(nn.Module):
    """Predicts class ``k`` at every pixel, logits (B, C, h, w), or per image, (B, C)."""

    def __init__(self, k: int, num_classes: int = 7, spatial: bool = True) -> None:
        super().__init__()
        self.k, self.c, self.spatial = k, num_classes, spatial

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = torch.zeros(len(x), self.c, *(x.shape[-2:] if self.spatial else ()))
        out[:, self.k] = 1.0
        return out


def test_unpressed_pixels_are_scored_as_background():
    """A network that says "ring" everywhere, on a 2 x 3 image pressed at 2 pixels labelled
    ring and palm: 1 ring hit of 2 pressed pixels, the 4 unpressed pixels background. Counted
    by hand: pixel accuracy 5/6, ring IoU 1/2, palm IoU 0, background IoU 1."""
    x = torch.zeros(1, 1, 2, 3)
    x[0, 0, 0, 0], x[0, 0, 1, 2] = 0.5, 0.2
    y = torch.zeros(1, 2, 3, dtype=torch.int64)
    y[0, 0, 0], y[0, 1, 2] = 4, 6
    res = evaluate_tensors(Constant(4), TensorData(x, y), 7)
    assert res.metrics["pixel_accuracy"] == pytest.approx(5 / 6)
    assert res.metrics["mean_iou"] == pytest.approx((1 + 0.5 + 0) / 3)
    pred = np.full((1, 2, 3), 4)
    want = np.array([[[4, 0, 0], [0, 0, 4]]])
    np.testing.assert_array_equal(unpressed_as_background(pred, x.numpy()), want)
    classify = evaluate_tensors(Constant(1, 2, spatial=False), TensorData(x, torch.tensor([1])), 2)
    assert classify.metrics["accuracy"] == 1.0  # classifiers are not masked
