"""Intervals over test subjects (learn.cluster_bootstrap) against a closed form (whole groups
right or wrong: binomial quantiles over groups) and a slow bootstrap that draws groups its own
way; and the report's columns."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from scipy.stats import binom

from learn import metrics as M
from learn.cluster_bootstrap import (
    STRATUM_SHIFT,
    group_counts,
    grouped_accuracy_interval,
    grouped_difference_interval,
    grouped_mean_iou_difference_interval,
    grouped_mean_iou_interval,
    sample_groups,
    sample_weights,
)
from learn.eval_report import write_report
from learn.evaluate import evaluate_checkpoint
from learn.significance import accuracy_interval, significance_markdown


def test_groups_are_subjects_then_instances_then_single_samples():
    subject = np.array([5, 5, -1, -1, -1, 7])
    instance = np.array([-1, -1, 5, 5, -1, -1])
    g = sample_groups(subject, instance)
    assert g[0] == g[1] == 5 and g[5] == 7  # subjects keep their ids
    assert g[2] == g[3] != g[0]  # instance 5 is not subject 5
    assert len({*g[[0, 2, 4, 5]]}) == 4 and g[4] >> STRATUM_SHIFT == 2
    assert group_counts(g) == {"subjects": 2, "object instances": 1, "unattributed samples": 1}
    assert len(set(sample_groups(None, None, n=3))) == 3  # image folders: every sample alone
    with pytest.raises(ValueError, match="sample count"):
        sample_groups(None, None)


def test_weights_draw_whole_groups_within_their_stratum():
    groups = sample_groups(
        np.array([0, 0, 0, 1, 2, 2, -1, -1, -1]), np.array([-1] * 6 + [10, 10, 11])
    )
    w = sample_weights(groups, resamples=200, seed=3)
    assert np.array_equal(w, sample_weights(groups, resamples=200, seed=3))
    assert np.all(w[:, 0] == w[:, 1]) and np.all(w[:, 1] == w[:, 2]) and np.all(w[:, 4] == w[:, 5])
    assert np.all(w[:, 6] == w[:, 7])
    # per resample: as many subjects drawn as there are (3), as many instances (2)
    assert np.all(w[:, 0] + w[:, 3] + w[:, 4] == 3) and np.all(w[:, 6] + w[:, 8] == 2)
    assert np.all(w[:, :6].sum(1) == 3 * 1 + w[:, 0] * 2 + w[:, 4])  # sizes 3, 1, 2


def test_whole_groups_right_or_wrong_give_binomial_quantiles_over_groups():
    """40 subjects of 10 prints each, 30 subjects all right, 10 all wrong: the subjects, not the
    400 prints, are the draws, so the accuracy's bootstrap law is Binomial(40, 0.75) / 40; its
    percentile ends are that law's quantiles (within one subject, the bootstrap's noise)."""
    g, right_groups = 40, 30
    groups = sample_groups(np.repeat(np.arange(g), 10), None)
    correct = (np.repeat(np.arange(g), 10) < right_groups).astype(float)
    lo, hi = grouped_accuracy_interval(correct, groups, resamples=4000)
    want = binom.ppf([0.025, 0.975], g, right_groups / g) / g  # 25/40 and 35/40
    assert (lo, hi) == pytest.approx(tuple(want), abs=1 / g + 1e-9)
    naive_lo, naive_hi = accuracy_interval(300, 400)  # per-print: too narrow
    assert hi - lo > 1.5 * (naive_hi - naive_lo)


def _slow_ends(stat, groups: np.ndarray, resamples: int, seed: int) -> tuple[float, float]:
    """A loop that draws group ids with replacement within each stratum (its own generator)
    and evaluates ``stat`` on the pooled samples of the drawn groups."""
    rng = np.random.default_rng(seed)
    by_stratum: dict[int, list[int]] = {}
    for code in np.unique(groups):
        by_stratum.setdefault(int(code) >> STRATUM_SHIFT, []).append(int(code))
    values = []
    for _ in range(resamples):
        picks = [rng.choice(codes, len(codes)) for codes in by_stratum.values()]
        rows = np.concatenate([np.flatnonzero(groups == c) for c in np.concatenate(picks)])
        values.append(stat(rows))
    return tuple(np.quantile(values, [0.025, 0.975]))


def test_accuracy_and_difference_against_a_slow_bootstrap():
    rng = np.random.default_rng(4)
    subject = np.repeat(np.arange(25), rng.integers(8, 30, 25))  # uneven subjects
    n_hand = len(subject)
    instance = np.repeat(100 + np.arange(60), rng.integers(2, 8, 60))
    groups = sample_groups(
        np.r_[subject, -np.ones(len(instance), int)], np.r_[-np.ones(n_hand, int), instance]
    )
    skill = np.r_[rng.uniform(0.6, 1.0, 25)[subject], rng.uniform(0.7, 1.0, 60)[instance - 100]]
    a = (rng.uniform(size=len(groups)) < skill).astype(float)
    b = np.where(rng.uniform(size=len(groups)) < 0.1, 1 - a, a)  # B differs on ~10 %
    lo, hi = grouped_accuracy_interval(a, groups, resamples=2000)
    ref = _slow_ends(lambda k: a[k].mean(), groups, 2000, 11)
    assert (lo, hi) == pytest.approx(ref, abs=0.006)
    assert lo < a.mean() < hi
    dlo, dhi = grouped_difference_interval(a, b, groups, resamples=2000)
    dref = _slow_ends(lambda k: (a[k] - b[k]).mean(), groups, 2000, 12)
    assert (dlo, dhi) == pytest.approx(dref, abs=0.006)
    assert grouped_difference_interval(a, a, groups) == (0.0, 0.0)


def test_mean_iou_against_a_slow_bootstrap():
    rng = np.random.default_rng(5)
    subject = np.repeat(np.arange(20), 12)
    hit = np.clip(rng.uniform(0.4, 0.95, 20)[subject] + rng.normal(0, 0.03, len(subject)), 0, 1)
    cms = np.zeros((len(subject), 3, 3))
    cms[:, 0, 0] = 500
    cms[:, 1, 1], cms[:, 1, 2] = 100 * hit, 100 * (1 - hit)
    cms[:, 2, 2], cms[:, 2, 1] = 80 * hit, 80 * (1 - hit)
    groups = sample_groups(subject, None)
    lo, hi = grouped_mean_iou_interval(cms, groups, resamples=2000)
    ref = _slow_ends(lambda k: M.mean_iou(torch.tensor(cms[k].sum(0))), groups, 2000, 13)
    assert (lo, hi) == pytest.approx(ref, abs=0.006)


def test_markdown_columns_and_rows_without_groups():
    groups = sample_groups(np.repeat(np.arange(10), 10), None).tolist()
    base = {"task": "classify", "test_indices": list(range(100)), "test_groups": groups}
    a = {**base, "cm": [[90, 10], [0, 0]], "errors": [{"index": i} for i in range(10)]}
    b = {**base, "cm": [[80, 20], [0, 0]], "errors": [{"index": i} for i in range(10, 30)]}
    text = "\n".join(significance_markdown([a, b], ["A", "B"]))
    assert "10 subjects" in text and "subjects resampled" in text
    ok_a = 1.0 - np.isin(np.arange(100), range(10))
    lo, hi = grouped_accuracy_interval(ok_a, np.asarray(groups))
    assert "| A | 100 | 90.00 |" in text and f"| {100 * lo:.2f}–{100 * hi:.2f} |" in text
    ok_b = 1.0 - np.isin(np.arange(100), range(10, 30))
    dlo, dhi = grouped_difference_interval(ok_a, ok_b, np.asarray(groups))
    assert f"| {100 * dlo:+.2f} to {100 * dhi:+.2f} |" in text
    old = {k: v for k, v in b.items() if k not in ("test_indices", "test_groups")}
    text = "\n".join(significance_markdown([a, old], ["A", "B"]))  # an older report's row
    assert text.count("| — |") == 2  # B's subject interval and the pair's


def test_evaluated_rows_record_their_test_subjects(checkpoints, tiny_dataset, tmp_path):
    from tactile.dataset import open_dataset

    reader = open_dataset(tiny_dataset)
    for arch in ("handsnet", "segnet"):
        row = evaluate_checkpoint(checkpoints[arch], tiny_dataset, time_runs=3)
        idx = np.asarray(row["test_indices"])
        want = sample_groups(
            reader["subject_id"][np.sort(idx)][np.argsort(np.argsort(idx))],
            reader["instance_id"][np.sort(idx)][np.argsort(np.argsort(idx))],
        )
        assert np.array_equal(row["test_groups"], want) and len(idx) == row["n_test"]
        if arch == "segnet":  # per-image matrices add up to the evaluator's pooled one
            assert np.array_equal(np.sum(row["per_image_cm"], axis=0), row["cm"])
            lo, hi = row["mean_iou_interval_groups"]
            assert lo <= row["metrics"]["mean_iou"] <= hi
            text = write_report([row], tmp_path / "r.md").read_text()
            assert f"| {100 * lo:.2f}–{100 * hi:.2f} |" in text


def _two_segmenters(seed: int = 6):
    """Per-image confusion matrices of two segmenters on the same 15 subjects x 10 images: B
    is A with some of its right pixels of class 2 turned wrong, more for some subjects."""
    rng = np.random.default_rng(seed)
    subject = np.repeat(np.arange(15), 10)
    hit = np.clip(rng.uniform(0.5, 0.95, 15)[subject] + rng.normal(0, 0.03, 150), 0, 1)
    a = np.zeros((150, 3, 3))
    a[:, 0, 0] = 400
    a[:, 1, 1], a[:, 1, 2] = 100 * hit, 100 * (1 - hit)
    a[:, 2, 2], a[:, 2, 0] = 60 * hit, 60 * (1 - hit)
    lost = a[:, 2, 2] * rng.uniform(0.0, 0.2, 15)[subject]
    b = a.copy()
    b[:, 2, 2] -= lost
    b[:, 2, 1] += lost
    return subject, a, b


def test_mean_iou_difference_against_a_slow_paired_bootstrap():
    subject, a, b = _two_segmenters()
    groups = sample_groups(subject, None)
    lo, hi = grouped_mean_iou_difference_interval(a, b, groups, resamples=2000)

    def diff(k):
        return M.mean_iou(torch.tensor(a[k].sum(0))) - M.mean_iou(torch.tensor(b[k].sum(0)))

    assert (lo, hi) == pytest.approx(_slow_ends(diff, groups, 2000, 14), abs=0.004)
    assert 0 < lo < diff(np.arange(150)) < hi  # B is worse on every subject
    single = sample_groups(None, None, n=150)
    ilo, ihi = grouped_mean_iou_difference_interval(a, b, single, resamples=2000)
    assert ihi - ilo < hi - lo  # images alike within a subject: redrawing images is narrower
    assert grouped_mean_iou_difference_interval(a, a, groups) == (0.0, 0.0)
    with pytest.raises(ValueError, match="same test images"):
        grouped_mean_iou_difference_interval(a, b[:10], groups)


def test_segmenter_pairs_in_the_report_section():
    from learn.significance import segmentation_markdown

    subject, a, b = _two_segmenters()
    groups = sample_groups(subject, None)
    rows = [
        {
            "n_test": 150,
            "metrics": {"mean_iou": M.mean_iou(torch.tensor(cm.sum(0)))},
            "mean_iou_interval": [0.5, 0.6],
            "mean_iou_interval_groups": [0.4, 0.7],
            "per_image_cm": cm.tolist(),
            "test_indices": list(range(150)),
            "test_groups": groups.tolist(),
        }
        for cm in (a, b)
    ]
    text = "\n".join(segmentation_markdown(rows, ["A", "B"]))
    lo, hi = grouped_mean_iou_difference_interval(a, b, groups)
    d = rows[0]["metrics"]["mean_iou"] - rows[1]["metrics"]["mean_iou"]
    assert f"| A | B | {100 * d:+.2f} |" in text
    assert f"| {100 * lo:+.2f} to {100 * hi:+.2f} |" in text
    other = dict(rows[1], test_indices=list(range(1, 151)))  # another test set: no pair
    assert "| A | B |" not in "\n".join(segmentation_markdown([rows[0], other], ["A", "B"]))
