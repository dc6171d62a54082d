"""Intervals that redraw whole test subjects, not single test samples (a cluster bootstrap).

The test split holds ~20 prints of each held-out person and several of each held-out object
instance; prints of one person are alike (one hand size, one way of touching), so they are not
independent draws and a per-sample interval is too narrow. Here every resample draws, with
replacement, as many subjects as the test split has (among its subjects), as many object
instances (among its instances) and as many unattributed samples (each its own group), and pools
every sample of each drawn group, as often as it is drawn. The strata keep the test split's mix
of hands and non-hands.

    groups = sample_groups(subject_id, instance_id)          # (S,) int64 group code per sample
    lo, hi = grouped_accuracy_interval(correct, groups)    # fractions
    lo, hi = grouped_mean_iou_interval(cms, groups)        # (S, C, C) per-image matrices
    lo, hi = grouped_mean_iou_difference_interval(cms_a, cms_b, groups)   # paired, A - B

Seeded (`BOOTSTRAP_SEED`): the same inputs give the same interval, bytes and all.
"""

from __future__ import annotations

import numpy as np

from learn.significance import BOOTSTRAP_SEED, LEVEL, N_RESAMPLES, batched_mean_iou

#: A group code is ``stratum << STRATUM_SHIFT | id``: 0 subjects, 1 object instances, 2 samples
#: with neither (each its own group, keyed by its position).
STRATUM_SHIFT = 40
STRATA = ("subjects", "object instances", "unattributed samples")


def sample_groups(
    subject: np.ndarray | None, instance: np.ndarray | None, n: int | None = None
) -> np.ndarray:
    """(S,) int64 group code of each test sample from its dataset ``subject_id`` and
    ``instance_id`` ((S,) ints, -1 where none; None when the data has no such field): its
    subject, else its object instance, else itself. ``n`` (S) when both are None."""
    known = subject if subject is not None else instance
    size = len(known) if known is not None else n
    if size is None:
        raise ValueError("sample_groups: give subject or instance ids, or the sample count n")
    none = np.full(size, -1, dtype=np.int64)
    subject = none if subject is None else np.asarray(subject, dtype=np.int64)
    instance = none if instance is None else np.asarray(instance, dtype=np.int64)
    if subject.shape != (size,) or instance.shape != (size,):
        raise ValueError("sample_groups: subject and instance ids must be (S,) arrays alike")
    own = (2 << STRATUM_SHIFT) | np.arange(size, dtype=np.int64)
    by_instance = np.where(instance >= 0, (1 << STRATUM_SHIFT) | instance, own)
    return np.where(subject >= 0, subject, by_instance)


def group_counts(groups: np.ndarray) -> dict[str, int]:
    """How many groups of each stratum (`STRATA` names) ``groups`` holds (non-empty only)."""
    strata = np.unique(np.asarray(groups, dtype=np.int64)) >> STRATUM_SHIFT
    return {STRATA[s]: int(np.sum(strata == s)) for s in range(len(STRATA)) if np.any(strata == s)}


def sample_weights(
    groups: np.ndarray, resamples: int = N_RESAMPLES, seed: int = BOOTSTRAP_SEED
) -> np.ndarray:
    """(B, S) float64: how many times each of the S test samples is drawn in each of B
    resamples, when groups are drawn with replacement within their stratum."""
    codes, inverse = np.unique(np.asarray(groups, dtype=np.int64), return_inverse=True)
    strata = codes >> STRATUM_SHIFT
    rng = np.random.default_rng(seed)
    counts = np.zeros((resamples, len(codes)))
    for stratum in np.unique(strata):
        cols = np.flatnonzero(strata == stratum)
        counts[:, cols] = rng.multinomial(
            len(cols), np.full(len(cols), 1.0 / len(cols)), size=resamples
        )
    return counts[:, inverse.ravel()]


def _ends(stats: np.ndarray, level: float) -> tuple[float, float]:
    lo, hi = np.quantile(stats, [(1 - level) / 2, (1 + level) / 2])
    return float(lo), float(hi)


def grouped_accuracy_interval(
    correct: np.ndarray, groups: np.ndarray, level: float = LEVEL, resamples: int = N_RESAMPLES
) -> tuple[float, float]:
    """Percentile interval (lo, hi) of an accuracy, fractions, from (S,) per-sample right (1) or
    wrong (0), test subjects and instances redrawn (`sample_weights`)."""
    w = sample_weights(groups, resamples)
    return _ends(w @ np.asarray(correct, dtype=np.float64) / w.sum(1), level)


def grouped_difference_interval(
    correct_a: np.ndarray,
    correct_b: np.ndarray,
    groups: np.ndarray,
    level: float = LEVEL,
    resamples: int = N_RESAMPLES,
) -> tuple[float, float]:
    """Percentile interval (lo, hi) of accuracy A minus accuracy B (fractions) on the same (S,)
    test samples, redrawn together by group: a paired comparison that allows for subjects."""
    diff = np.asarray(correct_a, dtype=np.float64) - np.asarray(correct_b, dtype=np.float64)
    w = sample_weights(groups, resamples)
    return _ends(w @ diff / w.sum(1), level)


def grouped_mean_iou_interval(
    cms: np.ndarray,
    groups: np.ndarray,
    level: float = LEVEL,
    resamples: int = N_RESAMPLES,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float]:
    """Percentile interval (lo, hi) of the pooled mIoU of (S, C, C) per-image confusion
    matrices (`learn.significance.per_image_confusion`), test subjects redrawn."""
    s, c = cms.shape[0], cms.shape[1]
    pooled = (sample_weights(groups, resamples, seed) @ cms.reshape(s, -1)).reshape(-1, c, c)
    return _ends(batched_mean_iou(pooled), level)


def grouped_mean_iou_difference_interval(
    cms_a: np.ndarray,
    cms_b: np.ndarray,
    groups: np.ndarray,
    level: float = LEVEL,
    resamples: int = N_RESAMPLES,
) -> tuple[float, float]:
    """Percentile interval (lo, hi) of mIoU A minus mIoU B (fractions) of two segmenters' (S, C,
    C) per-image confusion matrices on the same test images, redrawn together by group (pass
    ``sample_groups(None, None, n=S)`` to redraw single images): a paired comparison."""
    if cms_a.shape != cms_b.shape:
        raise ValueError(
            f"grouped_mean_iou_difference_interval: {cms_a.shape} against "
            f"{cms_b.shape}; give both the same test images and classes"
        )
    s, c = cms_a.shape[0], cms_a.shape[1]
    w = sample_weights(groups, resamples)
    a = batched_mean_iou((w @ cms_a.reshape(s, -1)).reshape(-1, c, c))
    b = batched_mean_iou((w @ cms_b.reshape(s, -1)).reshape(-1, c, c))
    return _ends(a - b, level)
