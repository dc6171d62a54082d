"""Shortcut features against hand-computed values on tiny images; the grouped held-out check."""

from __future__ import annotations

import numpy as np
import pytest

from learn.classical.shortcut import (
    FEATURE_NAMES,
    NONHAND_GROUP_OFFSET,
    bbox_px,
    blob_count,
    contact_area_px,
    group_ids,
    image_features,
    mean_intensity,
    shortcut_check,
    split_by_group,
)
from tactile.errors import DataError


def two_blobs() -> np.ndarray:
    """5 x 6 image: a 2 x 2 block of 100 (rows 0-1, cols 0-1), 50 at (2, 3) and (3, 4)
    and a 200 at (4, 5): corner to corner, one 8-connected chain."""
    im = np.zeros((5, 6), dtype=np.uint8)
    im[0:2, 0:2] = 100
    im[2, 3] = im[3, 4] = 50
    im[4, 5] = 200
    return im


def test_features_match_hand_computed_values() -> None:
    im = two_blobs()
    assert contact_area_px(im) == 7
    assert blob_count(im) == 2  # 8-connected: (2,3)-(3,4)-(4,5) is one diagonal chain
    assert mean_intensity(im) == pytest.approx((4 * 100 + 2 * 50 + 200) / 7)
    assert bbox_px(im) == (5, 6)


def test_separate_blobs_and_bbox() -> None:
    im = np.zeros((8, 8))
    im[1, 1] = 1.0
    im[1, 5:7] = 3.0
    assert blob_count(im) == 2
    assert bbox_px(im) == (1, 6)
    assert mean_intensity(im) == pytest.approx(7.0 / 3)


def test_empty_image_gives_zeros() -> None:
    feats = image_features(np.zeros((1, 4, 4), dtype=np.uint8))
    np.testing.assert_array_equal(feats, np.zeros((1, len(FEATURE_NAMES))))


def test_image_features_stack_and_shape_check() -> None:
    feats = image_features(np.stack([two_blobs(), np.zeros((5, 6), np.uint8)]))
    assert feats.shape == (2, 5)
    np.testing.assert_allclose(feats[0], [7, 2, 700 / 7, 5, 6])
    with pytest.raises(DataError, match="B, H, W"):
        image_features(np.zeros((4, 4)))


def test_group_ids_keep_subjects_and_instances_apart() -> None:
    g = group_ids(np.array([1, 0, 1, 0]), np.array([3, -1, 4, -1]), np.array([-1, 3, -1, 3]))
    np.testing.assert_array_equal(g, [3, 3 + NONHAND_GROUP_OFFSET, 4, 3 + NONHAND_GROUP_OFFSET])


def test_split_by_group_is_disjoint() -> None:
    groups = np.repeat(np.arange(20), 5)
    train, test = split_by_group(groups, 0.3, seed=1)
    assert len(train) + len(test) == 100
    assert not set(groups[train]) & set(groups[test])


def synthetic(n: int, separable: bool, rng: np.random.Generator):
    y = rng.integers(0, 2, n)
    x = rng.normal(size=(n, 5))
    if separable:
        x[:, 0] += 6.0 * y
    return x, y, np.arange(n) // 4


def test_shortcut_check_separable_and_random() -> None:
    rng = np.random.default_rng(0)
    res = shortcut_check(*synthetic(400, True, rng))
    assert res.accuracy > 0.98 and res.coefficients["area_px"] > 0
    assert res.n_train + res.n_test == 400
    chance = shortcut_check(*synthetic(400, False, rng))
    assert 0.35 < chance.accuracy < 0.65


def test_shortcut_check_needs_both_classes() -> None:
    with pytest.raises(DataError, match="both classes"):
        shortcut_check(np.zeros((4, 5)), np.ones(4), np.arange(4))
