"""Skin model: closed forms of each stage, invariants, seeded statistics."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from sim.skin.model import (
    FULL_SCALE_COUNTS,
    SkinConfig,
    SkinInstance,
    depth_to_pressure,
    force_consistent_pressure,
    lattice_spacing_m,
    quantize,
    spread_matrix,
    taxel_areas_m2,
)
from tactile.errors import ConfigError
from tactile.geometry.synthetic import hex_lattice_mm


def lattice_m(pitch_mm: float = 8.0) -> np.ndarray:
    flat = hex_lattice_mm(120.0, 120.0, pitch_mm) * 1e-3
    return np.column_stack([flat, np.zeros(len(flat))])


def test_foundation_law_linear_and_power() -> None:
    cfg = SkinConfig()
    d = np.array([-1e-3, 0.0, 1e-4, 1e-3])
    np.testing.assert_allclose(depth_to_pressure(d, cfg), [0.0, 0.0, 1e4, 1e5])
    stiff = SkinConfig(exponent=2.0, reference_depth_m=2e-3)
    # equal to the linear law at the reference depth, quadratic around it
    np.testing.assert_allclose(depth_to_pressure(np.array([2e-3, 1e-3]), stiff), [2e5, 5e4])


def test_spread_rows_sum_to_one_and_keep_uniform_field() -> None:
    pos = lattice_m()
    w = spread_matrix(pos, sigma_m=4e-3)  # 8 mm neighbours at two sigmas
    np.testing.assert_allclose(np.asarray(w.sum(axis=1)).ravel(), 1.0)
    np.testing.assert_allclose(w @ np.full(len(pos), 3.0), 3.0)
    # nearest neighbour at 8 mm gets exp(-2) of the centre's weight
    centre = int(np.argmin(np.linalg.norm(pos, axis=1)))
    row = w.getrow(centre).toarray().ravel()
    nbr = np.flatnonzero(np.isclose(np.linalg.norm(pos - pos[centre], axis=1), 8e-3))
    assert len(nbr) == 6
    np.testing.assert_allclose(row[nbr] / row[centre], np.exp(-2.0))


def test_zero_sigma_is_identity() -> None:
    pos = lattice_m()
    np.testing.assert_array_equal(spread_matrix(pos, 0.0).toarray(), np.eye(len(pos)))


def test_quantize_rounds_and_saturates() -> None:
    out = quantize(np.array([-5.0, 0.4, 0.6, 70000.0, 65534.6]))
    assert out.dtype == np.uint16
    np.testing.assert_array_equal(out, [0, 0, 1, FULL_SCALE_COUNTS, FULL_SCALE_COUNTS])


def test_noise_free_frame_keeps_truth_and_gain() -> None:
    pos = lattice_m()
    cfg = SkinConfig(
        spread_sigma_m=0.0,
        gain_spread=0.0,
        baseline_spread_counts=0.0,
        drift_std_counts_per_s=0.0,
        saturation_pa=0.0,  # a linear pad
    )
    skin = SkinInstance.create(pos, cfg, np.random.default_rng(0))
    depth = np.zeros(len(pos))
    depth[:3] = [1e-4, 5e-4, 5e-3]  # 10 kPa, 50 kPa, 500 kPa (beyond full scale)
    frame = skin.frame(depth, rng=None)
    np.testing.assert_allclose(frame.pressure_pa[:3], [1e4, 5e4, 5e5])
    expect = cfg.baseline_counts + cfg.counts_per_pa * np.array([1e4, 5e4])
    np.testing.assert_allclose(frame.reading[:2], np.rint(expect))
    assert frame.reading[2] == FULL_SCALE_COUNTS
    assert np.all(frame.reading[3:] == round(cfg.baseline_counts))
    # full scale pressure reaches exactly the top of the range
    assert cfg.baseline_counts + cfg.counts_per_pa * cfg.full_scale_pa == pytest.approx(65535)


def test_pads_saturate_as_the_closed_form() -> None:
    pos = lattice_m()
    cfg = SkinConfig(
        spread_sigma_m=0.0, gain_spread=0.0, baseline_spread_counts=0.0, drift_std_counts_per_s=0.0
    )
    assert cfg.saturation_pa == 5000.0  # the default, fitted to real prints (sim.skin.model)
    skin = SkinInstance.create(pos, cfg, np.random.default_rng(0))
    depth = np.zeros(len(pos))
    depth[:4] = [5e-7, 5e-5, 1e-4, 5e-3]  # 50 Pa, 5 kPa, 10 kPa, 500 kPa
    frame = skin.frame(depth, rng=None)
    np.testing.assert_allclose(frame.pressure_pa[:4], [50.0, 5e3, 1e4, 5e5])  # truth unsaturated
    read_pa = (frame.reading[:4] - cfg.baseline_counts) / cfg.counts_per_pa
    # p_sat (1 - e^(-p / p_sat)): 49.75 Pa, p_sat (1 - 1/e), p_sat (1 - 1/e^2), p_sat; within
    # half a count (rounding)
    expect = 5000.0 * (1.0 - np.exp(-np.array([0.01, 1.0, 2.0, 100.0])))
    np.testing.assert_allclose(read_pa, expect, atol=0.5 / cfg.counts_per_pa)
    linear = SkinInstance.create(pos, replace(cfg, saturation_pa=0.0), np.random.default_rng(0))
    lin_pa = (linear.frame(depth, rng=None).reading[:2] - cfg.baseline_counts) / cfg.counts_per_pa
    assert abs(read_pa[0] - lin_pa[0]) <= 1.0 / cfg.counts_per_pa  # light touches stay linear
    assert read_pa[1] < 0.64 * lin_pa[1]


def test_noise_and_drift_statistics_seeded() -> None:
    pos = lattice_m()
    cfg = SkinConfig()
    skin = SkinInstance.create(pos, cfg, np.random.default_rng(1))
    assert abs(np.std(skin.gain) - cfg.gain_spread) < 0.02
    assert abs(np.std(skin.baseline_counts) - cfg.baseline_spread_counts) < 60
    rng = np.random.default_rng(2)
    frames = np.array([skin.frame(np.zeros(len(pos)), rng).signal_counts for _ in range(50)])
    assert abs(frames.std() - cfg.noise_std_counts) < 5
    late = skin.frame(np.zeros(len(pos)), None, time_s=100.0).reading.astype(float)
    np.testing.assert_allclose(late, np.rint(skin.offset(100.0)), atol=0.5)
    again = SkinInstance.create(pos, cfg, np.random.default_rng(1))
    np.testing.assert_array_equal(again.gain, skin.gain)


def test_dead_modules_read_baseline_but_keep_truth() -> None:
    pos = lattice_m()
    modules = np.arange(len(pos)) // 12
    skin = SkinInstance.create(pos, SkinConfig(), np.random.default_rng(0))
    broken = skin.with_dead_modules(modules, 2, np.random.default_rng(3))
    assert broken.dead.sum() == 24
    depth = np.full(len(pos), 1e-4)
    frame = broken.frame(depth, None)
    assert np.all(frame.pressure_pa > 0)
    np.testing.assert_allclose(frame.signal_counts[broken.dead], 0.0, atol=0.5)


@pytest.mark.parametrize("field", ["stiffness_pa_per_m", "noise_std_counts", "full_scale_pa"])
def test_config_rejects_bad_values(field: str) -> None:
    with pytest.raises(ConfigError, match=field):
        SkinConfig(**{field: -1.0})


def test_taxel_areas_sum_to_the_mesh_area_and_fall_back_to_hex_cells() -> None:
    pos = np.array([[0.0, 0, 0], [0.01, 0, 0], [0.0, 0.02, 0], [0.01, 0.02, 0]])
    faces = np.array([[0, 1, 2], [1, 3, 2]])  # a 10 x 20 mm rectangle
    area = taxel_areas_m2(pos, faces)
    np.testing.assert_allclose(area, np.array([1, 2, 2, 1]) / 3 * 1e-4)
    assert area.sum() == pytest.approx(2e-4)
    hexes = lattice_m(8.0)
    np.testing.assert_allclose(taxel_areas_m2(hexes), 0.008**2 * np.sqrt(3) / 2)
    assert lattice_spacing_m(hexes) == pytest.approx(0.008)


def test_force_consistent_pressure_keeps_shape_and_resultant() -> None:
    base = np.array([0.0, 1e5, 2e5, 1e5, 0.0])
    area = np.array([1.0, 2.0, 1.0, 2.0, 1.0]) * 1e-4
    p = force_consistent_pressure(base, area, 6.0)
    assert p @ area == pytest.approx(6.0)
    np.testing.assert_allclose(p, base * (6.0 / (base @ area)))
    np.testing.assert_allclose(force_consistent_pressure(base, area, 12.0), 2 * p)  # linear in F
    np.testing.assert_array_equal(force_consistent_pressure(np.zeros(5), area, 6.0), 0.0)
    np.testing.assert_array_equal(force_consistent_pressure(base, area, 0.0), 0.0)


def test_skin_pressure_scales_to_the_sensed_force_unless_switched_off() -> None:
    pos = lattice_m()
    depth = np.where(np.linalg.norm(pos, axis=1) < 0.02, 1e-3, 0.0)
    for sigma in (0.0, 3e-3):
        skin = SkinInstance.create(pos, SkinConfig(spread_sigma_m=sigma), np.random.default_rng(0))
        assert skin.pressure(depth, 4.0) @ skin.area_m2 == pytest.approx(4.0, rel=0.02)
        np.testing.assert_allclose(skin.pressure(depth), skin.spread @ (1e8 * depth))  # no force
    elastic = SkinInstance.create(pos, SkinConfig(force_consistent=False), np.random.default_rng(0))
    np.testing.assert_allclose(elastic.pressure(depth, 4.0), elastic.pressure(depth))
    frame = skin.frame(depth, None, force_n=4.0)
    np.testing.assert_allclose(frame.pressure_pa, skin.pressure(depth, 4.0))
