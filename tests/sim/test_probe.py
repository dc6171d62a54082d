"""The force-controlled probe against elastic-foundation closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from sim.parts import get_part
from sim.probe import Probe, ProbeRig, calibration_curve, central_taxel, foundation_depth_m
from sim.skin import SkinConfig, SkinInstance
from tactile.errors import ConfigError

K = SkinConfig().stiffness_pa_per_m


def rig(part_name: str, probe: Probe, cfg: SkinConfig | None = None) -> ProbeRig:
    part = get_part(part_name)
    skin = SkinInstance.create(
        part.layout.positions_m, cfg or SkinConfig(), np.random.default_rng(0)
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
    cfg = SkinConfig(spread_sigma_m=0.0)
    r = rig("plate", Probe("cylinder", (0.025, 0.01)), cfg)
    result = r.press(20.0)
    under = result.contactor >= 0
    assert under.sum() >= 25
    np.testing.assert_allclose(result.pressure_pa[under], 20.0 / (np.pi * 0.025**2), rtol=0.03)
    np.testing.assert_array_equal(result.pressure_pa[~under], 0.0)


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
    curve = calibration_curve(part, Probe("sphere", (0.02,)), forces, central_taxel(part))
    assert np.all(np.diff(curve["summed_signal_counts"]) > 0)
    assert np.all(np.diff(curve["active"]) >= 0)
    assert curve["saturated"][0] == 0 and curve["saturated"][-1] > 0


def test_unknown_probe_shape() -> None:
    with pytest.raises(ConfigError, match="known: sphere, cylinder, box"):
        Probe("cone", (0.01,))
