"""Simulated subjects: reproducible, the paper's population statistics, unique ids, splits."""

from __future__ import annotations

import numpy as np
import pytest

from sim.contactors.hand import HandConfig
from sim.contactors.subjects import Subject, sample_subjects, split_subjects, truncated_normal
from tactile.errors import ConfigError


def test_same_seed_same_subjects_other_seed_other_subjects():
    a = sample_subjects(50, np.random.default_rng(3))
    b = sample_subjects(50, np.random.default_rng(3))
    c = sample_subjects(50, np.random.default_rng(4))
    assert a == b
    assert a != c


def test_population_statistics_match_the_paper():
    subjects = sample_subjects(2000, np.random.default_rng(0))
    length = np.array([s.hand.length_m for s in subjects])
    breadth = np.array([s.hand.breadth_m for s in subjects])
    right = np.mean([s.handedness == "right" for s in subjects])
    assert length.min() >= 0.15 and length.max() <= 0.22
    assert length.mean() == pytest.approx(0.18, abs=0.002)
    assert right == pytest.approx(0.778, abs=0.03)
    assert np.corrcoef(length, breadth)[0, 1] > 0.7  # breadth grows with length
    assert np.all((breadth / length >= 0.38) & (breadth / length <= 0.52))


def test_ids_unique_and_hands_follow_handedness():
    subjects = sample_subjects(300, np.random.default_rng(1), first_id=100)
    ids = [s.subject_id for s in subjects]
    assert len(set(ids)) == len(ids)
    assert ids[0] == "s0100"
    for s in subjects:
        assert s.hand.prefix == ("rh_" if s.handedness == "right" else "lh_")
        assert 0.0025 <= s.tissue_depth_m <= 0.0045
        assert 0.4 <= s.force_scale <= 2.5


def test_split_keeps_test_subjects_unseen_in_training():
    subjects = sample_subjects(90, np.random.default_rng(2))
    train, test = split_subjects(subjects, 0.2, np.random.default_rng(5))
    assert len(test) == 18 and len(train) == 72
    assert not {s.subject_id for s in train} & {s.subject_id for s in test}
    again = split_subjects(subjects, 0.2, np.random.default_rng(5))
    assert again == (train, test)


def test_split_rejects_duplicate_ids():
    a = sample_subjects(5, np.random.default_rng(0))
    with pytest.raises(ConfigError, match="duplicate"):
        split_subjects(a + a, 0.5, np.random.default_rng(0))


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"force_scale": 0.0}, "force_scale"),
        ({"approach_deg": 120.0}, "approach_deg"),
        ({"pose_noise_deg": -1.0}, "pose_noise_deg"),
        ({"subject_id": ""}, "subject_id"),
    ],
)
def test_subject_out_of_range_names_the_field(kwargs, field):
    with pytest.raises(ConfigError, match=field):
        Subject(**{"subject_id": "s0001", "hand": HandConfig(), **kwargs})


def test_truncated_normal_stays_in_bounds():
    draws = truncated_normal(np.random.default_rng(0), 10_000, 0.0, 1.0, (-1.0, 2.0))
    assert draws.shape == (10_000,)
    assert draws.min() >= -1.0 and draws.max() <= 2.0
    # reference: mean of N(0, 1) truncated to [-1, 2] = (phi(-1) - phi(2)) / (Phi(2) - Phi(-1))
    assert draws.mean() == pytest.approx(0.2297, abs=0.02)
