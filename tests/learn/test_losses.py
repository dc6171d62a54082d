"""Losses: median-frequency weights by hand, weighted CE against its definition, Dice bounds."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from learn.config import LOSSES
from learn.train.losses import (
    SegmentationLoss,
    class_pixel_counts,
    median_frequency_weights,
    soft_dice_loss,
    weighted_cross_entropy,
)
from tactile.errors import ConfigError, DataError


def test_median_frequency_weights_by_hand():
    # image A (4 px): 3 × class 0, 1 × class 1; image B (4 px): 2 × class 0, 2 × class 2.
    labels = [np.array([[0, 0], [0, 1]]), np.array([[0, 2], [0, 2]])]
    class_px, image_px = class_pixel_counts(labels, num_classes=4)
    assert class_px.tolist() == [5, 1, 2, 0]
    assert image_px.tolist() == [8, 4, 4, 0]
    freq = np.array([5 / 8, 1 / 4, 2 / 4])
    expected = np.median(freq) / freq
    np.testing.assert_allclose(median_frequency_weights(class_px, image_px)[:3], expected)
    assert median_frequency_weights(class_px, image_px)[3] == 1.0  # unseen class: neutral


def test_class_pixel_counts_batches_and_errors():
    batch = torch.tensor([[[0, 1], [1, 1]], [[2, 2], [2, 2]]])
    assert [c.tolist() for c in class_pixel_counts([batch], 3)] == [[1, 3, 4], [4, 4, 4]]
    with pytest.raises(DataError, match=r"0\.\.2"):
        class_pixel_counts([np.array([[3]])], 3)
    with pytest.raises(ConfigError, match="no labelled"):
        median_frequency_weights(np.zeros(3), np.zeros(3))


def test_weighted_cross_entropy_matches_definition():
    g = torch.Generator().manual_seed(0)
    logits = torch.randn(2, 3, 4, 5, generator=g)
    target = torch.randint(0, 3, (2, 4, 5), generator=g)
    w = torch.tensor([0.5, 2.0, 1.0])
    nll = -logits.log_softmax(1).gather(1, target[:, None])[:, 0]
    expected = (w[target] * nll).sum() / w[target].sum()
    torch.testing.assert_close(weighted_cross_entropy(logits, target, w), expected)
    unweighted = weighted_cross_entropy(logits, target)
    torch.testing.assert_close(unweighted, nll.mean())


def test_soft_dice_bounds_and_gradient():
    target = torch.randint(0, 4, (2, 6, 7), generator=torch.Generator().manual_seed(1))
    perfect = 50.0 * torch.nn.functional.one_hot(target, 4).movedim(-1, 1).float()
    assert soft_dice_loss(perfect, target).item() == pytest.approx(0.0, abs=1e-6)
    assert soft_dice_loss(perfect, target, generalized=True).item() == pytest.approx(0, abs=1e-6)
    wrong = perfect.roll(1, dims=1)
    assert soft_dice_loss(wrong, target).item() > 0.95
    logits = torch.zeros(2, 4, 6, 7, requires_grad=True)
    soft_dice_loss(logits, target).backward()
    assert logits.grad.abs().sum() > 0


def test_segmentation_loss_by_name():
    logits = torch.randn(1, 3, 4, 4)
    target = torch.randint(0, 3, (1, 4, 4))
    for name in LOSSES:
        weights = [1.0, 2.0, 3.0] if name == "weighted_ce" else None
        assert SegmentationLoss(name, weights)(logits, target).ndim == 0
    with pytest.raises(ConfigError, match="choose one of"):
        SegmentationLoss("focal")
    with pytest.raises(ConfigError, match="weights"):
        SegmentationLoss("weighted_ce")


def test_ce_dice_is_the_sum_of_mean_nll_and_soft_dice_by_loops():
    g = torch.Generator().manual_seed(2)
    logits = torch.randn(2, 3, 4, 5, generator=g, dtype=torch.float64)
    target = torch.randint(0, 3, (2, 4, 5), generator=g)
    p = logits.softmax(1).numpy()
    t = target.numpy()
    nll, inter, total = [], np.zeros(3), np.zeros(3)
    for b, i, j in np.ndindex(t.shape):
        nll.append(-np.log(p[b, t[b, i, j], i, j]))
        for c in range(3):
            g_c = float(t[b, i, j] == c)
            inter[c] += p[b, c, i, j] * g_c
            total[c] += p[b, c, i, j] + g_c
    expected = np.mean(nll) + 1 - np.mean((2 * inter + 1) / (total + 1))
    got = SegmentationLoss("ce_dice")(logits, target).item()
    assert got == pytest.approx(expected, rel=1e-12)
    # Starting from all-background logits, the CE term still pushes the other classes up.
    start = torch.zeros(1, 3, 4, 5, requires_grad=True)
    start.data[:, 0] = 5.0
    SegmentationLoss("ce_dice")(start, target[:1]).backward()
    assert (
        start.grad[:, 1:][torch.nn.functional.one_hot(target[:1], 3).movedim(-1, 1)[:, 1:] > 0] < 0
    ).all()
