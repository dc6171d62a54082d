"""`tactile.dataset.readout`: raw counts to pascals, checked against values worked by hand."""

from __future__ import annotations

import numpy as np
import pytest

from tactile.dataset.readout import LEGACY_FLOOR_SIGMAS, Readout
from tactile.errors import DataError

ATTRS = {
    "skin_counts_per_pa": 0.5,
    "skin_baseline_counts": np.array([4000.0, 4100.0, 3900.0]),
    "skin_drift_counts_per_s": np.array([2.0, -1.0, 0.0]),
    "skin_noise_floor_counts": 300.0,
}


def test_baseline_drift_floor_and_gain_worked_by_hand():
    raw = np.array([[4500, 4399, 4200], [4305, 4500, 4300]], dtype=np.uint16)
    t = np.array([0.0, 2.5])  # s
    # frame 0: signals 500, 299, 300 -> 500 / 0.5 Pa; 299 and 300 are not above the floor
    # frame 1: 4305 - 4000 - 5 = 300 (at the floor), 4500 - 4100 + 2.5 = 402.5, 400
    want = np.array([[1000.0, 0.0, 0.0], [0.0, 805.0, 800.0]])
    np.testing.assert_allclose(Readout.of(ATTRS).pressure_pa(raw, t), want)
    np.testing.assert_allclose(Readout.of(ATTRS).pressure_pa(raw[1], 2.5), want[1])


def test_missing_attrs_are_the_identity_and_legacy_floor_comes_from_the_config():
    raw = np.array([0, 250, 400])
    np.testing.assert_array_equal(Readout.of({}).pressure_pa(raw), [0.0, 250.0, 400.0])
    legacy = {"config": {"episode": {"skin": {"noise_std_counts": 100.0}}}}
    assert Readout.of(legacy).floor_counts == LEGACY_FLOOR_SIGMAS * 100.0
    np.testing.assert_array_equal(Readout.of(legacy).pressure_pa(raw), [0.0, 0.0, 400.0])


def test_no_time_removes_no_drift():
    raw = np.array([4400, 4400, 4400])
    np.testing.assert_allclose(Readout.of(ATTRS).pressure_pa(raw), [800.0, 0.0, 1000.0])


def test_a_non_positive_gain_is_refused_naming_the_fix():
    with pytest.raises(DataError, match="counts-per-pa"):
        Readout.of({"skin_counts_per_pa": 0.0})


def test_attrs_describe_the_readout_they_came_from():
    ro = Readout.of(ATTRS)
    back = Readout.of(ro.attrs())
    raw = np.array([[4500, 4399, 4200]])
    np.testing.assert_array_equal(back.pressure_pa(raw, [1.0]), ro.pressure_pa(raw, [1.0]))
    assert back.floor_counts == 300.0 and back.gain_counts_per_pa == 0.5
