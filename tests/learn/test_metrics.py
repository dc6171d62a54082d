"""Metrics against slow, obviously-correct loops over a confusion matrix (Long et al., Sec. 5)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from learn.metrics import (
    accuracy,
    confusion_matrix,
    frequency_weighted_iou,
    mean_class_accuracy,
    mean_iou,
    percent_by_true_class,
    pixel_accuracy,
    segmentation_scores,
    without_true_class,
)
from tactile.errors import DataError


def slow_confusion(target, pred, k):
    cm = [[0] * k for _ in range(k)]
    for t, p in zip(np.ravel(target).tolist(), np.ravel(pred).tolist(), strict=True):
        cm[t][p] += 1
    return cm


def slow_scores(cm):
    """Long et al.'s four formulas written out with loops, absent classes (t_i = 0) skipped."""
    k = len(cm)
    t = [sum(cm[i]) for i in range(k)]
    col = [sum(cm[j][i] for j in range(k)) for i in range(k)]
    present = [i for i in range(k) if t[i] > 0]
    pixel = sum(cm[i][i] for i in range(k)) / sum(t)
    mean_acc = sum(cm[i][i] / t[i] for i in present) / len(present)
    ious = {i: cm[i][i] / (t[i] + col[i] - cm[i][i]) for i in present}
    mean_iu = sum(ious.values()) / len(present)
    fw = sum(t[i] * ious[i] for i in present) / sum(t)
    return {"pixel_accuracy": pixel, "mean_accuracy": mean_acc, "mean_iou": mean_iu, "fw_iou": fw}


@pytest.mark.parametrize("seed", range(20))
def test_scores_match_slow_reference_on_random_cases(seed):
    rng = np.random.default_rng(seed)
    k = int(rng.integers(2, 8))
    shape = (int(rng.integers(1, 4)), int(rng.integers(1, 9)), int(rng.integers(1, 9)))
    present = rng.choice(k, size=int(rng.integers(1, k + 1)), replace=False)  # absent classes
    target = rng.choice(present, size=shape)
    pred = np.where(rng.random(shape) < 0.6, target, rng.integers(0, k, shape))
    cm = confusion_matrix(torch.from_numpy(target), torch.from_numpy(pred), k)
    assert cm.tolist() == slow_confusion(target, pred, k)
    assert confusion_matrix(target.astype(np.uint8), pred, k).tolist() == cm.tolist()
    for name, value in segmentation_scores(cm).items():
        assert math.isclose(value, slow_scores(slow_confusion(target, pred, k))[name]), name


def test_closed_form_small_case():
    # true: [0, 0, 0, 1, 1, 2]; predicted: [0, 0, 1, 1, 2, 2]; class 3 absent (never true).
    cm = confusion_matrix(torch.tensor([0, 0, 0, 1, 1, 2]), torch.tensor([0, 0, 1, 1, 2, 2]), 4)
    assert cm.tolist() == [[2, 1, 0, 0], [0, 1, 1, 0], [0, 0, 1, 0], [0, 0, 0, 0]]
    assert pixel_accuracy(cm) == accuracy(cm) == pytest.approx(4 / 6)
    assert mean_class_accuracy(cm) == pytest.approx((2 / 3 + 1 / 2 + 1) / 3)
    ious = [2 / 3, 1 / 3, 1 / 2]  # n_ii / (t_i + predicted_i - n_ii)
    assert mean_iou(cm) == pytest.approx(sum(ious) / 3)
    assert frequency_weighted_iou(cm) == pytest.approx((3 * ious[0] + 2 * ious[1] + ious[2]) / 6)
    pct = percent_by_true_class(cm)
    assert torch.allclose(pct[0], torch.tensor([200 / 3, 100 / 3, 0, 0], dtype=torch.float64))
    assert torch.isnan(pct[3]).all()


def test_absent_predicted_only_class_lowers_no_mean():
    # class 2 is predicted but never true: it is skipped in the means, yet counts as a false
    # positive in class 0's IoU.
    cm = torch.tensor([[1, 0, 1], [0, 2, 0], [0, 0, 0]])
    assert mean_class_accuracy(cm) == pytest.approx((0.5 + 1) / 2)
    assert mean_iou(cm) == pytest.approx((0.5 + 1) / 2)


def test_ignore_index_and_bad_input():
    cm = confusion_matrix(torch.tensor([0, 255, 1]), torch.tensor([0, 1, 1]), 2, ignore_index=255)
    assert cm.tolist() == [[1, 0], [0, 1]]
    with pytest.raises(DataError, match=r"0\.\.1"):
        confusion_matrix(torch.tensor([0, 2]), torch.tensor([0, 1]), 2)
    with pytest.raises(DataError, match="target"):
        confusion_matrix(torch.zeros(3), torch.zeros(4), 2)
    assert math.isnan(accuracy(torch.zeros(2, 2)))


@pytest.mark.parametrize("seed", range(10))
def test_scores_without_background_equal_scores_on_the_hand_pixels(seed):
    """Zeroing the background's row scores the truth's hand pixels alone: Long et al.'s four
    formulas written out on those pixels (a hand pixel predicted as background is wrong; a
    background pixel predicted as a part counts nowhere), absent parts skipped."""
    rng = np.random.default_rng(seed)
    truth = np.where(rng.random(4000) < 0.7, 0, rng.choice([1, 2, 3, 4, 6], 4000))  # 5 absent
    pred = np.where(rng.random(4000) < 0.5, truth, rng.integers(0, 7, 4000))
    cm = confusion_matrix(torch.from_numpy(truth), torch.from_numpy(pred), 7)
    got = segmentation_scores(without_true_class(cm))
    hand = truth != 0
    t, p = truth[hand], pred[hand]
    parts = [c for c in range(1, 7) if (t == c).any()]
    ious = {c: np.sum((t == c) & (p == c)) / np.sum((t == c) | (p == c)) for c in parts}
    want = {
        "pixel_accuracy": np.mean(t == p),
        "mean_accuracy": np.mean([np.mean(p[t == c] == c) for c in parts]),
        "mean_iou": np.mean(list(ious.values())),
        "fw_iou": sum(np.sum(t == c) * ious[c] for c in parts) / t.size,
    }
    for name, value in want.items():
        assert got[name] == pytest.approx(value), name
    assert cm[0].sum() > 0 and without_true_class(cm)[0].sum() == 0  # the input is untouched
    with pytest.raises(DataError, match=r"0\.\.6"):
        without_true_class(cm, 7)
