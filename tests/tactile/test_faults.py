"""Faults: blind spots measured on the map, nested removal, dead modules, stuck-at, gain drift."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from tactile.errors import ConfigError
from tactile.geometry.synthetic import hex_lattice_mm
from tactile.images.faults import (
    blind_spots,
    dead_modules,
    gain_drift,
    nested_removal,
    stuck_at,
    zero_taxels,
)

UV = hex_lattice_mm(120.0, 200.0, 11.0)  # (N, 2) taxel uv, mm


def test_blind_spot_radius_on_the_map() -> None:
    radius = 15.0
    blind = blind_spots(UV, 3, radius, np.random.default_rng(0))
    dist = np.linalg.norm(UV[:, None] - UV[None], axis=-1)
    # the centres are blind taxels whose disk is fully blind; find them among the blind ones
    full = [i for i in np.flatnonzero(blind) if blind[dist[i] <= radius].all()]
    covered = (dist[:, full] <= radius).any(axis=1)
    np.testing.assert_array_equal(blind, covered)  # blind <=> within radius of a centre
    assert 3 <= blind.sum() < len(UV)


def test_blind_spots_exact_centres() -> None:
    """With the rng replayed, the centres are known: check both directions exactly."""
    uv = UV.copy()
    uv[5] = np.nan  # an unplaced taxel is never blind nor a centre
    placed = np.flatnonzero(np.isfinite(uv).all(axis=1))
    centres = uv[np.random.default_rng(7).choice(placed, size=4, replace=False)]
    blind = blind_spots(uv, 4, 12.0, np.random.default_rng(7))
    d = np.linalg.norm(uv[:, None] - centres[None], axis=-1)
    expected = (np.nan_to_num(d, nan=np.inf) <= 12.0).any(axis=1)
    np.testing.assert_array_equal(blind, expected)
    assert not blind[5]


def test_blind_spots_reproducible_and_zeroed() -> None:
    a = blind_spots(UV, 2, 20.0, np.random.default_rng(3))
    b = blind_spots(UV, 2, 20.0, np.random.default_rng(3))
    np.testing.assert_array_equal(a, b)
    p = np.ones((2, len(UV)))
    out = zero_taxels(p, a)
    assert not out[:, a].any() and (out[:, ~a] == 1).all()
    assert not blind_spots(UV, 0, 20.0, np.random.default_rng(3)).any()


def test_nested_removal_is_nested_and_reproducible() -> None:
    fractions = [0.0, 0.1, 0.2, 0.5, 0.9]
    kept = nested_removal(500, fractions, np.random.default_rng(1))
    assert [len(k) for k in kept] == [500, 450, 400, 250, 50]
    for larger_kept, smaller_kept in itertools.pairwise(kept):
        assert set(smaller_kept) <= set(larger_kept)
    again = nested_removal(500, fractions, np.random.default_rng(1))
    for k1, k2 in zip(kept, again, strict=True):
        np.testing.assert_array_equal(k1, k2)
    other = nested_removal(500, fractions, np.random.default_rng(2))
    assert not np.array_equal(kept[1], other[1])
    assert all(np.all(np.diff(k) > 0) for k in kept)  # sorted, unique


def test_dead_modules_kill_whole_modules() -> None:
    module_ids = np.repeat(np.arange(10), 10)
    module_ids[:3] = -1
    dead = dead_modules(module_ids, 3, np.random.default_rng(4))
    killed = np.unique(module_ids[dead])
    assert len(killed) == 3 and -1 not in killed
    np.testing.assert_array_equal(dead, np.isin(module_ids, killed))
    with pytest.raises(ConfigError, match=r"0\.\.10"):
        dead_modules(module_ids, 11, np.random.default_rng(4))


def test_stuck_at_and_gain_drift() -> None:
    p = np.random.default_rng(5).random((4, 100)) * 1e3
    faulty, stuck = stuck_at(p, 0.1, np.random.default_rng(6))
    assert stuck.sum() == 10
    np.testing.assert_array_equal(faulty[:, ~stuck], p[:, ~stuck])
    assert (faulty[:, stuck] == faulty[0, stuck]).all()  # constant over frames
    fixed, _ = stuck_at(p, 0.2, np.random.default_rng(6), value=0.0)
    assert (fixed == 0).sum(axis=1).min() >= 20
    drifted, gains = gain_drift(p, 0.1, np.random.default_rng(7))
    np.testing.assert_allclose(drifted, p * gains)
    np.testing.assert_array_equal(gain_drift(p, 0.1, np.random.default_rng(7))[0], drifted)
    assert gains.shape == (100,) and 0.5 < gains.min() and gains.max() < 2.0


@pytest.mark.parametrize("fractions", [[0.1, 1.5], [-0.1]])
def test_bad_fractions_raise(fractions: list[float]) -> None:
    with pytest.raises(ConfigError, match=r"\[0, 1\]"):
        nested_removal(10, fractions, np.random.default_rng(0))


def test_bad_blind_spot_arguments_raise() -> None:
    with pytest.raises(ConfigError, match="n_spots"):
        blind_spots(UV, len(UV) + 1, 5.0, np.random.default_rng(0))
    with pytest.raises(ConfigError, match="radius_mm"):
        blind_spots(UV, 1, -1.0, np.random.default_rng(0))
    with pytest.raises(ConfigError, match=r"\(N, 2\)"):
        blind_spots(np.zeros((4, 3)), 1, 1.0, np.random.default_rng(0))
