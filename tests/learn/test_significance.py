"""Accuracy intervals, McNemar's test and the mIoU bootstrap against closed forms and slow
references."""

from __future__ import annotations

from math import comb

import numpy as np
import pytest
import torch

from learn import metrics as M
from learn.eval_report import write_report
from learn.evaluate import evaluate_checkpoint
from learn.significance import (
    accuracy_interval,
    batched_mean_iou,
    mcnemar_p,
    mean_iou_interval,
    paired,
    per_image_confusion,
    significance_markdown,
)


def _tail_at_least(k: int, n: int, p: float) -> float:
    return sum(comb(n, i) * p**i * (1 - p) ** (n - i) for i in range(k, n + 1))


def _reference_interval(k: int, n: int, alpha: float = 0.05) -> tuple[float, float]:
    """Clopper–Pearson by bisection on exact binomial tail sums: the lower end is the p at
    which P(X >= k) = alpha / 2, the upper the p at which P(X <= k) = alpha / 2."""

    def solve(f, target):  # f increasing in p on [0, 1]
        lo, hi = 0.0, 1.0
        for _ in range(60):
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if f(mid) < target else (lo, mid)
        return (lo + hi) / 2

    low = 0.0 if k == 0 else solve(lambda p: _tail_at_least(k, n, p), alpha / 2)
    high = 1.0 if k == n else solve(lambda p: _tail_at_least(k + 1, n, p), 1 - alpha / 2)
    return low, high


def test_interval_closed_forms():
    n = 40  # all right: the lower end is (alpha / 2) ** (1 / n); none right: mirrored
    assert accuracy_interval(n, n) == pytest.approx((0.025 ** (1 / n), 1.0))
    assert accuracy_interval(0, n) == pytest.approx((0.0, 1 - 0.025 ** (1 / n)))


@pytest.mark.parametrize("k, n", [(1, 7), (50, 100), (91, 100), (966, 1052), (3, 500)])
def test_interval_matches_the_slow_reference(k, n):
    assert accuracy_interval(k, n) == pytest.approx(_reference_interval(k, n), abs=1e-9)
    lo, hi = accuracy_interval(k, n)  # and the interval of the errors is its mirror
    assert accuracy_interval(n - k, n) == pytest.approx((1 - hi, 1 - lo), abs=1e-12)


def test_interval_refuses_impossible_counts():
    with pytest.raises(ValueError, match="n_correct <= n"):
        accuracy_interval(11, 10)


def _reference_mcnemar(b: int, c: int) -> float:
    n = b + c
    return min(1.0, 2 * sum(comb(n, i) for i in range(min(b, c) + 1)) / 2**n)


@pytest.mark.parametrize("b, c", [(1, 9), (9, 1), (15, 5), (36, 19), (7, 7), (0, 3), (0, 0)])
def test_mcnemar_matches_the_exact_binomial_sum(b, c):
    assert mcnemar_p(b, c) == pytest.approx(_reference_mcnemar(b, c), rel=1e-12)


def _row(wrong: range, n: int = 100) -> dict:
    """A two-class classifier row that gets the samples ``wrong`` wrong (all true class 0)."""
    return {
        "task": "classify",
        "cm": [[n - len(wrong), len(wrong)], [0, 0]],
        "errors": [{"index": int(i)} for i in wrong],
    }


def test_paired_counts_and_markdown():
    a, b = _row(range(10)), _row(range(5, 25))  # A: 90 %, B: 80 %; they share 5 errors
    c = paired(a, b)
    assert (c["only_a_right"], c["only_b_right"]) == (15, 5)
    assert c["difference"] == pytest.approx(0.10) and c["p"] == pytest.approx(
        _reference_mcnemar(15, 5)
    )
    text = "\n".join(significance_markdown([a, b], ["A", "B"]))
    lo, hi = _reference_interval(90, 100)
    assert f"| A | 100 | 90.00 | {100 * lo:.2f}–{100 * hi:.2f} |" in text
    assert f"| A | B | +10.00 | 15 | 5 | {_reference_mcnemar(15, 5):.3f} |" in text
    # a row that lists no errors keeps its interval but is left out of the pairs
    for unlisted in ({"cm": b["cm"]}, {"cm": b["cm"], "errors": None}):  # None: image folders
        alone = "\n".join(significance_markdown([a, unlisted], ["A", "B"]))
        assert "| B | 100 | 80.00 |" in alone and "McNemar" not in alone


def test_report_has_the_section(checkpoints, tiny_dataset, tmp_path):
    row = evaluate_checkpoint(checkpoints["handsnet"], tiny_dataset, time_runs=3)
    same = dict(row, checkpoint="/runs/b/best.pt")  # the same predictions: nothing to tell
    text = write_report([row, same], tmp_path / "r.md").read_text()
    cm = np.asarray(row["cm"])
    assert "## Classification: how sure the accuracies are" in text
    assert f"| {cm.sum()} | {100 * np.trace(cm) / cm.sum():.2f} |" in text
    assert "| 0 | 0 | 1.000 |" in text


def test_batched_mean_iou_matches_the_metric_function():
    rng = np.random.default_rng(0)
    cms = rng.integers(0, 50, size=(20, 7, 7)).astype(np.float64)
    cms[::3, 4, :] = 0  # class 4 absent from the truth of every third matrix: skipped
    cms[::5, :, 2] = 0  # and class 2 never predicted in others
    expected = [M.mean_iou(torch.tensor(cm)) for cm in cms]
    assert batched_mean_iou(cms) == pytest.approx(expected, rel=1e-12)


def test_per_image_confusion_counts_pixels():
    rng = np.random.default_rng(1)
    pred, truth = rng.integers(0, 4, (5, 6, 7)), rng.integers(0, 4, (5, 6, 7))
    cms = per_image_confusion(pred, truth, 4)
    for k in range(5):  # one image at a time, the slow way
        slow = np.zeros((4, 4))
        for t, p in zip(truth[k].ravel(), pred[k].ravel(), strict=True):
            slow[t, p] += 1
        assert np.array_equal(cms[k], slow)


def test_mean_iou_interval_against_a_slow_bootstrap():
    """The vectorised bootstrap against a loop that resamples image indices its own way: the
    two ends agree within 0.5 mIoU points (2,000 resamples each, fixed seeds), and the interval
    holds the pooled mIoU; identical images leave no spread."""
    rng = np.random.default_rng(2)
    s = 300
    hit = rng.uniform(0.3, 0.95, s)  # images of uneven difficulty
    cms = np.zeros((s, 3, 3))
    cms[:, 0, 0] = 500
    cms[:, 1, 1], cms[:, 1, 2] = 100 * hit, 100 * (1 - hit)
    cms[:, 2, 2], cms[:, 2, 1] = 80 * hit[::-1], 80 * (1 - hit[::-1])
    lo, hi = mean_iou_interval(cms, resamples=2000)
    slow_rng = np.random.default_rng(99)
    boot = [M.mean_iou(torch.tensor(cms[slow_rng.integers(0, s, s)].sum(0))) for _ in range(2000)]
    ref_lo, ref_hi = np.quantile(boot, [0.025, 0.975])
    assert lo == pytest.approx(ref_lo, abs=0.005) and hi == pytest.approx(ref_hi, abs=0.005)
    assert lo < M.mean_iou(torch.tensor(cms.sum(0))) < hi and hi - lo > 0.01
    same = np.repeat(cms[:1], 50, axis=0)
    assert mean_iou_interval(same) == pytest.approx((M.mean_iou(torch.tensor(same[0])),) * 2)


def test_segmenter_row_carries_its_interval(checkpoints, tiny_dataset, tmp_path):
    row = evaluate_checkpoint(checkpoints["segnet"], tiny_dataset, time_runs=3)
    lo, hi = row["mean_iou_interval"]
    assert lo <= row["metrics"]["mean_iou"] <= hi
    text = write_report([row], tmp_path / "r.md").read_text()
    assert "## Segmentation: how sure the mIoUs are" in text
    assert f"| {100 * row['metrics']['mean_iou']:.2f} | {100 * lo:.2f}–{100 * hi:.2f} |" in text
