"""How sure a test accuracy is, and whether two classifiers really differ on one test set.

A test set of ~1,000 samples cannot tell 91.8 % from 92.3 %: the report says so with each
classifier's exact binomial (Clopper–Pearson) interval, and compares every two classifiers
scored on the same test samples with McNemar's exact test, which looks only at the samples
exactly one of the two gets right (the pairing makes it far sharper than two intervals).
A segmenter's mIoU gets a percentile bootstrap interval over its test images.

Both treat test samples as independent; prints of one held-out person are alike, so those
intervals are too narrow. Rows that record their test samples' subjects (``test_groups``) also
get intervals that redraw whole subjects and object instances (`learn.cluster_bootstrap`): an
accuracy's, every pair's difference in accuracy, and a segmenter's mIoU; segmenters that record
per-image confusion matrices (``per_image_cm``) are compared pairwise, mIoU A − B with paired
bootstrap intervals (images, then subjects, redrawn).

    lo, hi = accuracy_interval(966, 1052)        # (0.900, 0.934)
    p = mcnemar_p(only_a_right=10, only_b_right=25)
"""

from __future__ import annotations

from itertools import combinations

import numpy as np
from scipy.stats import binomtest

#: Confidence level of the report's intervals.
LEVEL = 0.95
#: Bootstrap resamples of a segmenter's test images, and their seed (fixed: same report bytes).
N_RESAMPLES, BOOTSTRAP_SEED = 1000, 0


def accuracy_interval(n_correct: int, n: int, level: float = LEVEL) -> tuple[float, float]:
    """Exact (Clopper–Pearson) two-sided interval of an accuracy, as fractions (lo, hi), from
    ``n_correct`` right of ``n`` test samples; ValueError when the counts are impossible."""
    if not 0 <= n_correct <= n or n < 1:
        raise ValueError(
            f"accuracy_interval: need 0 <= n_correct <= n and n >= 1, got {n_correct} of {n}"
        )
    ci = binomtest(n_correct, n).proportion_ci(confidence_level=level, method="exact")
    return float(ci.low), float(ci.high)


def mcnemar_p(only_a_right: int, only_b_right: int) -> float:
    """Two-sided p of McNemar's exact test: under "A and B are equally accurate" each sample
    that exactly one of them gets right is A's with probability 1/2 (1.0 when there is none)."""
    if only_a_right < 0 or only_b_right < 0:
        raise ValueError("mcnemar_p: counts of discordant samples must be >= 0")
    n = only_a_right + only_b_right
    return 1.0 if n == 0 else float(binomtest(only_a_right, n, 0.5).pvalue)


def per_image_confusion(pred: np.ndarray, truth: np.ndarray, num_classes: int) -> np.ndarray:
    """Every test image's own confusion matrix, (S, C, C) float64 pixel counts (rows: truth),
    of (S, h, w) predicted and true class ids."""
    s, c = len(truth), num_classes
    codes = (
        np.arange(s)[:, None] * c * c
        + truth.reshape(s, -1).astype(np.int64) * c
        + pred.reshape(s, -1)
    )
    return np.bincount(codes.ravel(), minlength=s * c * c).reshape(s, c, c).astype(np.float64)


def batched_mean_iou(cm: np.ndarray) -> np.ndarray:
    """Long et al.'s mean IU of each of (B, C, C) confusion matrices, (B,): classes absent from
    a matrix's ground truth skipped (as `learn.metrics.mean_iou`, vectorised)."""
    n_ii, t_i, p_i = np.diagonal(cm, axis1=1, axis2=2), cm.sum(2), cm.sum(1)
    present = t_i > 0
    iou = np.divide(n_ii, t_i + p_i - n_ii, out=np.zeros_like(n_ii), where=present)
    return (iou * present).sum(1) / present.sum(1)


def mean_iou_interval(
    cms: np.ndarray, level: float = LEVEL, resamples: int = N_RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> tuple[float, float]:
    """Percentile bootstrap interval (lo, hi) of the pooled mIoU of (S, C, C) per-image
    confusion matrices: the test images drawn with replacement ``resamples`` times (each image
    its own group of `learn.cluster_bootstrap.grouped_mean_iou_interval`)."""
    from learn.cluster_bootstrap import grouped_mean_iou_interval, sample_groups

    return grouped_mean_iou_interval(
        cms, sample_groups(None, None, n=len(cms)), level, resamples, seed
    )


def _wrong(r: dict) -> set[int]:
    return {int(e["index"]) for e in r["errors"]}


def _correct(r: dict) -> np.ndarray | None:
    """(S,) 1 / 0 per test sample (``test_indices`` order) of a classifier row that records its
    test samples and their groups, else None."""
    if r.get("test_groups") is None or r.get("errors") is None:
        return None
    return 1.0 - np.isin(np.asarray(r["test_indices"]), list(_wrong(r)))


def _grouped(r: dict) -> str:
    """The subject-level accuracy interval of a row, "lo–hi" in %, or "—" without groups."""
    from learn.cluster_bootstrap import grouped_accuracy_interval

    ok = _correct(r)
    return "—" if ok is None else _span(grouped_accuracy_interval(ok, r["test_groups"]))


def _grouped_pair(a: dict, b: dict) -> str:
    """Subject-level interval of accuracy A minus B in points, or "—" unless both rows record
    the same test samples and groups."""
    from learn.cluster_bootstrap import grouped_difference_interval

    ok_a, ok_b = _correct(a), _correct(b)
    if ok_a is None or ok_b is None or a["test_indices"] != b["test_indices"]:
        return "—"
    return _signed(grouped_difference_interval(ok_a, ok_b, a["test_groups"]))


def _span(interval) -> str:
    lo, hi = interval
    return f"{100 * lo:.2f}–{100 * hi:.2f}"


def _groups_sentence(rows: list[dict]) -> list[str]:
    """What the subject-level intervals redraw, from the first row that records groups."""
    from learn.cluster_bootstrap import group_counts

    first = next((r for r in rows if r.get("test_groups") is not None), None)
    if first is None:
        return []
    counts = ", ".join(f"{n} {name}" for name, n in group_counts(first["test_groups"]).items())
    return [
        "",
        f"*Subjects resampled*: a percentile bootstrap ({N_RESAMPLES:,} resamples, "
        f"seeded) that redraws the test split's {counts} — each with all its samples — "
        "instead of single samples. Prints of one person are alike, so this is the honest "
        "width; the per-sample interval is too narrow.",
    ]


def paired(a: dict, b: dict) -> dict[str, float]:
    """McNemar's comparison of two classifier report rows on the same test samples (rows of
    `learn.evaluate` carry every misclassified sample's dataset index in ``errors``):
    ``only_a_right``, ``only_b_right``, ``difference`` (accuracy of A minus B, fraction), ``p``."""
    wa, wb = _wrong(a), _wrong(b)
    only_a, only_b = len(wb - wa), len(wa - wb)
    return {
        "only_a_right": only_a,
        "only_b_right": only_b,
        "difference": (only_a - only_b) / int(np.sum(a["cm"])),
        "p": mcnemar_p(only_a, only_b),
    }


def _paired_rows(rows: list[dict], labels: list[str]) -> list[tuple[dict, str]]:
    """The rows (with labels) that list their errors by sample index, when they all have as
    many test samples (one `handskin evaluate` run on a handskin dataset: one test split)."""
    listed = [
        (r, lab) for r, lab in zip(rows, labels, strict=True) if r.get("errors") is not None
    ]  # None: scored on image folders, not listed
    return listed if len({int(np.sum(r["cm"])) for r, _ in listed}) == 1 else []


def significance_markdown(rows: list[dict], labels: list[str]) -> list[str]:
    """The report section on classifier rows (with their table labels): each accuracy's
    interval and, when the rows share their test samples, every pair's McNemar test."""
    if not rows:
        return []
    out = _interval_head(
        "Classification: how sure the accuracies are",
        f"Each accuracy with its exact {100 * LEVEL:g} % binomial "
        "(Clopper–Pearson) interval over the test samples, and with test "
        "subjects resampled:",
        "test samples",
        "accuracy %",
        rows,
    )
    for r, lab in zip(rows, labels, strict=True):
        cm = np.asarray(r["cm"])
        k, n = int(np.trace(cm)), int(cm.sum())
        out.append(
            f"| {lab} | {n:,} | {100 * k / n:.2f} | {_span(accuracy_interval(k, n))} | "
            f"{_grouped(r)} |"
        )
    listed = _paired_rows(rows, labels)
    pairs = list(combinations(listed, 2))
    if not pairs:
        return [*out, ""]
    unpaired = [lab for lab in labels if lab not in {la for _, la in listed}]
    out += [
        "",
        "Every two classifiers on the same test samples, McNemar's exact test on the "
        "samples exactly one of them gets right (p two-sided; a small p says the difference "
        "is not test-set luck among independent samples). The last column redraws whole "
        "test subjects instead: when its interval holds 0, the difference could come from "
        "which persons and objects were held out:",
        "",
        "| A | B | A − B (points) | only A right | only B right | p | "
        f"A − B {100 * LEVEL:g} % interval, subjects resampled (points) |",
        "|---|---|---|---|---|---|---|",
    ]
    for (ra, la), (rb, lb) in pairs:
        c = paired(ra, rb)
        out.append(
            f"| {la} | {lb} | {100 * c['difference']:+.2f} | {c['only_a_right']} | "
            f"{c['only_b_right']} | {_p(c['p'])} | {_grouped_pair(ra, rb)} |"
        )
    if unpaired:
        out += [
            "",
            "Not paired (their rows list no per-sample errors): " + ", ".join(unpaired) + ".",
        ]
    return [*out, ""]


def segmentation_markdown(rows: list[dict], labels: list[str]) -> list[str]:
    """The report section on segmenter rows that carry a ``mean_iou_interval``."""
    shown = [(r, lab) for r, lab in zip(rows, labels, strict=True) if r.get("mean_iou_interval")]
    if not shown:
        return []
    out = _interval_head(
        "Segmentation: how sure the mIoUs are",
        f"Each mIoU with its {100 * LEVEL:g} % percentile bootstrap interval "
        f"({N_RESAMPLES:,} resamples of the test images, seeded), and with "
        "test subjects resampled:",
        "test images",
        "mIoU %",
        [r for r, _ in shown],
    )
    for r, lab in shown:
        grouped = r.get("mean_iou_interval_groups")
        out.append(
            f"| {lab} | {r['n_test']:,} | {100 * r['metrics']['mean_iou']:.2f} | "
            f"{_span(r['mean_iou_interval'])} | {_span(grouped) if grouped else '—'} |"
        )
    return [*out, *_segmenter_pairs(shown), ""]


def _segmenter_pairs(shown: list[tuple[dict, str]]) -> list[str]:
    """Every two segmenters that record per-image confusion matrices of the same test images:
    the mIoU difference with paired intervals, images and subjects redrawn."""
    from learn.cluster_bootstrap import grouped_mean_iou_difference_interval as diff_interval
    from learn.cluster_bootstrap import sample_groups

    listed = [(r, lab) for r, lab in shown if r.get("per_image_cm") is not None]
    pairs = [
        (a, b)
        for a, b in combinations(listed, 2)
        if a[0].get("test_indices") == b[0].get("test_indices")
    ]
    if not pairs:
        return []
    out = [
        "",
        "Every two segmenters on the same test images: mIoU A − B with paired "
        f"{100 * LEVEL:g} % intervals (both redrawn together: single images, then whole "
        "test subjects); an interval that holds 0 leaves the order open:",
        "",
        "| A | B | A − B (points) | interval, images resampled | interval, subjects resampled |",
        "|---|---|---|---|---|",
    ]
    for (ra, la), (rb, lb) in pairs:
        cms_a, cms_b = np.asarray(ra["per_image_cm"], float), np.asarray(rb["per_image_cm"], float)
        images = diff_interval(cms_a, cms_b, sample_groups(None, None, n=len(cms_a)))
        groups = ra.get("test_groups")
        subjects = (
            "—" if groups is None else _signed(diff_interval(cms_a, cms_b, np.asarray(groups)))
        )
        d = ra["metrics"]["mean_iou"] - rb["metrics"]["mean_iou"]
        out.append(f"| {la} | {lb} | {100 * d:+.2f} | {_signed(images)} | {subjects} |")
    return out


def _signed(interval) -> str:
    lo, hi = interval
    return f"{100 * lo:+.2f} to {100 * hi:+.2f}"


def _interval_head(
    title: str, sentence: str, count: str, score: str, rows: list[dict]
) -> list[str]:
    """A section's heading, its sentences and the head of its table of intervals."""
    return [
        f"## {title}",
        "",
        sentence,
        *_groups_sentence(rows),
        "",
        f"| method | {count} | {score} | {100 * LEVEL:g} % interval % | "
        f"{100 * LEVEL:g} % interval, subjects resampled % |",
        "|---|---|---|---|---|",
    ]


def _p(p: float) -> str:
    return "< 0.001" if p < 0.001 else f"{p:.3f}"
