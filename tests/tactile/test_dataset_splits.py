"""Train/test split: subjects and instances disjoint, stratified, ~70/30, deterministic."""

from __future__ import annotations

import numpy as np
import pytest

from tactile.dataset import split_indices
from tactile.dataset.splits import units
from tactile.errors import DataError


def population(seed: int = 0):
    """30 subjects with 10..40 hand samples each, 40 instances with 5..30 non-hand samples each,
    shuffled."""
    rng = np.random.default_rng(seed)
    subj = np.repeat(np.arange(30), rng.integers(10, 41, 30))
    inst = np.repeat(np.arange(40), rng.integers(5, 31, 40))
    is_hand = np.r_[np.ones(len(subj)), np.zeros(len(inst))].astype(np.uint8)
    subject_id = np.r_[subj, np.full(len(inst), -1)]
    instance_id = np.r_[np.full(len(subj), -1), inst]
    order = rng.permutation(len(is_hand))
    return is_hand[order], subject_id[order], instance_id[order]


def test_groups_disjoint_fractions_and_both_classes():
    is_hand, subject_id, instance_id = population()
    split = split_indices(is_hand, subject_id, instance_id, seed=4)
    train, test = split.train, split.test
    assert np.array_equal(np.sort(np.r_[train, test]), np.arange(len(is_hand)))
    for ids in (subject_id, instance_id):
        both = set(ids[train]) & set(ids[test]) - {-1}
        assert not both
    for c in (0, 1):
        frac = np.isin(np.flatnonzero(is_hand == c), train).mean()
        assert abs(frac - 0.7) < 0.03
        assert (is_hand[test] == c).any() and (is_hand[train] == c).any()
    assert abs(len(train) / len(is_hand) - 0.7) < 0.03
    assert split.report["train_fraction"] == pytest.approx(len(train) / len(is_hand))
    assert split.report["n_test_hand"] == int((is_hand[test] == 1).sum())


def test_deterministic_from_the_seed():
    data = population()
    a, b = split_indices(*data, seed=4), split_indices(*data, seed=4)
    c = split_indices(*data, seed=5)
    assert np.array_equal(a.train, b.train) and np.array_equal(a.test, b.test)
    assert not np.array_equal(a.train, c.train)


def test_samples_with_both_ids_link_subjects_and_instances():
    subject_id = np.array([0, 0, 1, 1, 2, -1, -1])
    instance_id = np.array([-1, 5, 5, -1, -1, 6, -1])
    unit = units(subject_id, instance_id)
    assert len(set(unit[:4])) == 1  # subject 0 - instance 5 - subject 1
    assert len(set(unit)) == 4  # {0..3}, {4}, {5}, {6}
    split = split_indices(None, subject_id, instance_id, seed=0)
    for ids in (subject_id, instance_id):
        assert not (set(ids[split.train]) & set(ids[split.test])) - {-1}


def test_samples_without_ids_are_split_one_by_one():
    split = split_indices(np.array([1, 0] * 50), seed=1)
    assert len(split.train) == 70 and len(split.test) == 30


def test_bad_fraction_is_refused():
    with pytest.raises(DataError, match=r"train_fraction must be in \(0, 1\)"):
        split_indices(np.ones(4), train_fraction=1.0)


def test_keyed_split_matches_the_slow_reference_draw_by_draw(keyed_reference):
    reference, sides_of = keyed_reference
    is_hand, subject_id, instance_id = population()
    for seed, stream in ((4, 0), (4, 1), (11, 0)):
        split = split_indices(
            is_hand, subject_id, instance_id, seed=seed, method="keyed", stream=stream
        )
        sides = sides_of(subject_id, instance_id, split.train)
        assert sides == reference(set(sides), seed, stream=stream)
    assert np.array_equal(np.sort(np.r_[split.train, split.test]), np.arange(len(is_hand)))


def test_keyed_sides_do_not_depend_on_sample_counts_or_on_other_units(keyed_reference):
    """Another part (other rejections: other samples per unit) and another n (more units): every
    unit both datasets hold keeps its side; the greedy split moves some."""
    a = population(seed=0)
    rng = np.random.default_rng(9)
    keep = rng.random(len(a[0])) < 0.8  # a fifth of the samples rejected on the other skin
    b = tuple(x[keep] for x in a)
    extra_subj = np.repeat(np.arange(30, 60), 12)  # a larger dataset: 30 more subjects
    c = (
        np.r_[a[0], np.ones(len(extra_subj), np.uint8)],
        np.r_[a[1], extra_subj],
        np.r_[a[2], np.full(len(extra_subj), -1)],
    )
    sides_of = keyed_reference[1]
    keyed = [
        sides_of(d[1], d[2], split_indices(*d, seed=4, method="keyed").train) for d in (a, b, c)
    ]
    greedy = [sides_of(d[1], d[2], split_indices(*d, seed=4).train) for d in (a, b, c)]
    for k in (1, 2):
        common = keyed[0].keys() & keyed[k].keys()
        assert len(common) == 70
        assert all(keyed[0][u] == keyed[k][u] for u in common)
        assert any(greedy[0][u] != greedy[k][u] for u in common)


def test_keyed_fraction_follows_the_binomial_spread():
    """2,000 one-sample subjects: the train fraction is a binomial(2000, 0.7) share, within 4
    standard deviations (0.041) of 0.7, and another stream draws other sides."""
    subject_id = np.arange(2000)
    split = split_indices(None, subject_id, None, seed=3, method="keyed")
    sd = np.sqrt(0.7 * 0.3 / 2000)
    assert abs(len(split.train) / 2000 - 0.7) < 4 * sd
    other = split_indices(None, subject_id, None, seed=3, method="keyed", stream=1)
    agree = np.isin(split.train, other.train).sum() + np.isin(split.test, other.test).sum()
    assert abs(agree / 2000 - (0.7**2 + 0.3**2)) < 4 * np.sqrt(0.58 * 0.42 / 2000)


def test_keyed_split_keeps_both_sides_for_two_units_of_a_class():
    """Two subjects whose draws are both above 0.001 (almost surely): one is moved to train."""
    split = split_indices(
        np.array([1, 1, 1, 1]),
        np.array([0, 0, 1, 1]),
        None,
        seed=0,
        train_fraction=0.001,
        method="keyed",
    )
    assert len(split.train) == 2 and len(split.test) == 2


def test_unknown_split_method_is_refused():
    with pytest.raises(DataError, match="method 'random' unknown; choose one of greedy, keyed"):
        split_indices(np.ones(4), method="random")
