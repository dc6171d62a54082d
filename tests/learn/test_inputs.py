"""Network-input rule: segmentation inputs on their labels' support, and checkpoints that record
the rule (a segmenter trained before it is refused, a classifier is not)."""

from __future__ import annotations

import numpy as np
import pytest
from torch import nn

from learn import config as C
from learn.checkpoint import inputs_stale, make_checkpoint, model_from_checkpoint
from learn.inputs import INPUTS, net_input
from learn.models import create_model
from learn.train import RunConfig
from tactile.config import to_dict
from tactile.errors import DataError


def test_net_input_by_task_on_a_closed_form_case():
    """A single lit pixel of an (8, 8) image halved to (4, 4): the blur spreads it over the
    output, the segmentation input keeps only the pixel whose centre-rule source is lit, at no
less than the image's smallest positive value."""
    img = np.zeros((8, 8), np.float32)
    img[3, 5] = 1.0  # output (1, 2) samples source (floor(1.5 * 2), floor(2.5 * 2)) = (3, 5)
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
