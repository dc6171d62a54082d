"""The force-controlled probe against elastic-foundation closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from sim.episode.probe import Probe, ProbeRig, calibration_curve, central_taxel, foundation_depth_m
from sim.skin.model import SkinConfig, SkinInstance
from sim.skin.parts import get_part
from tactile.errors import ConfigError

K = SkinConfig().stiffness_pa_per_m


def rig(part_name: str, probe: Probe, cfg: SkinConfig | None = None) -> ProbeRig:
    part = get_part(part_name)
    skin = SkinInstance.create(
        part.layout.positions_m, cfg or SkinConfig(), np.random.default_rng(0), part.sensor_faces
    )
    return ProbeRig(part, probe, central_taxel(part), skin)


def test_foundation_closed_forms() -> None:
    sphere, punch = Probe("sphere", (0.02,)), Probe("box", (0.01, 0.02, 0.01))
    d = foundation_depth_m(sphere, 5.0, K)
    assert np.pi * K * 0.02 * d**2 == pytest.approx(5.0)
    assert foundation_depth_m(punch, 8.0, K) == pytest.approx(8.0 / (K * 8e-4))
    assert foundation_depth_m(sphere, 0.0, K) == 0.0


@pytest.mark.parametrize("part_name", ["plate", "forearm"])
@pytest.mark.parametrize("force_n", [1.0, 10.0])
def test_sphere_settles_at_the_foundation_depth(part_name: str, force_n: float) -> None:
    result = rig(part_name, Probe("sphere", (0.02,))).press(force_n)
    assert result.depth_m == pytest.approx(result.target_depth_m, rel=0.02)


def test_flat_punch_gives_uniform_pressure_force_over_area() -> None:
    """Force-consistent pressure (`sim.skin.model`): a flat punch reads a uniform F / A under it,
    with A the pressed taxels' area on the sensor mesh (sum(p A) = F); that area samples the punch's
    pi r^2 (8 mm pitch, r = 25 mm, the rim and the mesh's holes at module corners: 0.84 pi r^2)."""
    cfg = SkinConfig(spread_sigma_m=0.0)
    r = rig("plate", Probe("cylinder", (0.025, 0.01)), cfg)
    result = r.press(20.0)
    under = result.contactor >= 0
    area = r.skin.area_m2[under]
    assert under.sum() >= 25
    assert float(result.pressure_pa @ r.skin.area_m2) == pytest.approx(20.0, rel=0.05)
    np.testing.assert_allclose(result.pressure_pa[under], 20.0 / area.sum(), rtol=1e-6)
    assert area.sum() == pytest.approx(np.pi * 0.025**2, rel=0.2)
    np.testing.assert_array_equal(result.pressure_pa[~under], 0.0)


def test_punch_doubling_the_force_doubles_every_pressure() -> None:
    """A flat punch (r = 20 mm, spread on): Σ p A = F within 5 %, and at twice the force the same
    taxels read twice the pressure (a flat face's depth profile keeps its shape)."""
    r = rig("plate", Probe("cylinder", (0.02, 0.01)))
    one, two = r.press(8.0), r.press(16.0)
    assert float(one.pressure_pa @ r.skin.area_m2) == pytest.approx(8.0, rel=0.05)
    np.testing.assert_array_equal(one.contactor >= 0, two.contactor >= 0)
    np.testing.assert_allclose(two.pressure_pa, 2.0 * one.pressure_pa, rtol=1e-3, atol=1e-6)


def test_contact_radius_sets_the_active_taxels() -> None:
    part = get_part("plate")
    r = rig("plate", Probe("sphere", (0.05,)))
    centre = part.layout.positions_m[r.taxel]
    for force in (2.0, 8.0, 20.0):
        result = r.press(force)
        a = np.sqrt(2 * 0.05 * result.depth_m)
        rho = np.linalg.norm(part.layout.positions_m - centre, axis=1)
        active = result.contactor >= 0
        assert np.all(rho[active] <= a) and np.all(active[rho < 0.98 * a])


def test_calibration_saturates_and_grows_monotonically() -> None:
    part = get_part("plate")
    forces = np.linspace(0.0, 40.0, 9)
    probe, taxel = Probe("sphere", (0.02,)), central_taxel(part)
    linear = calibration_curve(part, probe, forces, taxel, SkinConfig(saturation_pa=0.0))
    # a taxel clipped at full scale holds its reading until the contact reaches the next ring of
    # pads (8 mm pitch; the 2 mm spread does not reach it): the sum never falls
    assert np.all(np.diff(linear["summed_signal_counts"]) >= 0)
    assert np.all(np.diff(linear["active"]) >= 0)
    assert linear["saturated"][0] == 0 and linear["saturated"][-1] > 0  # the ADC's full scale
    # the default pads level off before the converter does: the same presses read less, the
    # hardest under half as much, and no taxel reaches 65535
    pads = calibration_curve(part, probe, forces, taxel)
    summed = pads["summed_signal_counts"]  # one pad levels off until the next ring is reached
    assert np.all(np.diff(summed) >= 0) and summed[-1] > 5 * summed[1]
    assert not pads["saturated"].any()
    assert np.all(pads["summed_signal_counts"][1:] < linear["summed_signal_counts"][1:])
    assert pads["summed_signal_counts"][-1] < 0.5 * linear["summed_signal_counts"][-1]


def test_unknown_probe_shape() -> None:
    with pytest.raises(ConfigError, match="known: sphere, cylinder, box"):
        Probe("cone", (0.01,))
