"""A force-controlled probe (sphere, flat cylinder or box indenter) for tests and calibration.

The probe sits on a slide joint along the inward normal of a taxel and a motor pushes it with the
commanded force. MuJoCo's soft contact sets how deep it sinks; the probe's contact stiffness is
tuned so that it settles at the depth an elastic (Winkler) foundation of modulus k gives:

- sphere of radius R: F = π k R δ²   (contact radius a = sqrt(2 R δ))
- flat cylinder of radius r (axis along the normal): F = k π r² δ
- box with half extents (hx, hy, hz), face down: F = 4 k hx hy δ

so force, depth and the foundation pressures agree (sum of p·area ≈ F); the skin model then scales
them to the sensed force exactly (`sim.skin.model`, force-consistent pressure: `ProbeRig.press`
passes the solver's force on the sensorized region). In MuJoCo's direct
solref format with constant impedance d, a single contact rests at r = (1 - d) F / (m s); the
stiffness s starts from that and is corrected by the measured depth (flat faces make 4 contacts).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.episode.frames import SENSED_RADIUS_SPACINGS, contact_forces_n
from sim.episode.scene import Contactor, SkinScene
from sim.skin.model import SkinConfig, SkinInstance
from sim.skin.parts import Part
from sim.skin.readout import link_contacts
from tactile.errors import ConfigError

IMPEDANCE = 0.95  # constant solimp d of the probe contact: depth then scales as 1/stiffness
SETTLE_S = 0.4  # s of simulated time to settle (critically damped, time constants < 0.1 s)
PROBE_SHAPES = ("sphere", "cylinder", "box")


@dataclass(frozen=True)
class Probe:
    """Indenter geometry (m) and mass (kg). size_m: sphere (R,), cylinder (r, half-length),
    box half extents (hx, hy, hz)."""

    shape: str = "sphere"
    size_m: tuple[float, ...] = (0.010,)
    mass_kg: float = 0.05

    def __post_init__(self) -> None:
        if self.shape not in PROBE_SHAPES:
            raise ConfigError(
                f"unknown probe shape {self.shape!r}; known: {', '.join(PROBE_SHAPES)}"
            )

    @property
    def height_m(self) -> float:
        """Distance from the probe centre to its face touching the skin (m)."""
        return self.size_m[0] if self.shape == "sphere" else self.size_m[-1]


def foundation_depth_m(probe: Probe, force_n: float, stiffness_pa_per_m: float) -> float:
    """Indentation depth (m) of the probe into a Winkler foundation under force_n (N)."""
    if force_n <= 0:
        return 0.0
    if probe.shape == "sphere":
        return float(np.sqrt(force_n / (np.pi * stiffness_pa_per_m * probe.size_m[0])))
    area = (
        np.pi * probe.size_m[0] ** 2 if probe.shape == "cylinder" else 4 * np.prod(probe.size_m[:2])
    )
    return float(force_n / (stiffness_pa_per_m * area))


def contact_params(stiffness: float) -> tuple[tuple[float, float], tuple[float, ...]]:
    """Direct-format solref (-stiffness, -damping), critically damped, and constant solimp."""
    return (-stiffness, -2.0 * np.sqrt(stiffness)), (IMPEDANCE, IMPEDANCE, 0.001, 0.5, 2.0)


@dataclass(frozen=True)
class PressResult:
    """Settled probe state: commanded force (N), target and settled depth (m), readout, frame."""

    force_n: float
    target_depth_m: float
    depth_m: float
    contactor: np.ndarray
    pressure_pa: np.ndarray
    signal_counts: np.ndarray
    reading: np.ndarray


class ProbeRig:
    """A part with one force-controlled probe above taxel `taxel` (layout index)."""

    def __init__(
        self, part: Part, probe: Probe, taxel: int, skin: SkinInstance, clearance_m: float = 2e-4
    ) -> None:
        self.probe, self.skin, self.taxel = probe, skin, taxel
        point = part.layout.positions_m[taxel]
        normal = part.layout.normals[taxel]
        self.start_m = point + normal * (probe.height_m + clearance_m)
        self.clearance_m = clearance_m
        contactor = Contactor(
            "probe",
            probe.shape,
            probe.size_m,
            tuple(self.start_m),
            tuple(-normal),
            label=1,
            mass_kg=probe.mass_kg,
            max_force_n=1e3,
        )
        self.scene = SkinScene(part, (contactor,))
        self.geom = self.scene.model.geom("obj_probe").id

    def _settle(self, force_n: float, stiffness: float) -> float:
        solref, solimp = contact_params(stiffness)
        self.scene.model.geom_solref[self.geom] = solref
        self.scene.model.geom_solimp[self.geom] = solimp
        self.scene.reset()
        self.scene.set_force("probe", force_n)
        self.scene.step(round(SETTLE_S / self.scene.model.opt.timestep))
        return self.scene.contactor_depth_m("probe") - self.clearance_m

    def sensed_force_n(self, depth_m: np.ndarray) -> float:
        """Normal force (N) of the probe's contacts near the pressed taxels (depth (N,) m > 0)."""
        m, d, readout = self.scene.model, self.scene.data, self.scene.readout
        pressed = readout.positions_m(d, np.flatnonzero(depth_m > 0))
        radius = SENSED_RADIUS_SPACINGS * self.skin.spacing_m
        contacts = link_contacts(m, d, readout.link_body)
        return contact_forces_n(m, d, contacts, pressed, radius)[1]

    def press(
        self,
        force_n: float,
        rng: np.random.Generator | None = None,
        max_iter: int = 8,
        rtol: float = 0.02,
    ) -> PressResult:
        """Push with force_n (N), settle, and read the skin (rng None: noise-free reading).

        The contact stiffness is re-tuned until the settled depth is within rtol of the target
        (depth falls monotonically with stiffness; damped multiplicative updates).
        """
        target = foundation_depth_m(self.probe, force_n, self.skin.cfg.stiffness_pa_per_m)
        depth = 0.0
        self.scene.reset()
        stiffness = (1 - IMPEDANCE) * force_n / (self.probe.mass_kg * max(target, 1e-12))
        for _ in range(max_iter if target > 0 else 0):
            depth = self._settle(force_n, stiffness)
            if abs(depth / target - 1.0) < rtol:
                break
            stiffness *= float(np.clip(max(depth, 1e-9) / target, 0.1, 10.0)) ** 0.8
        frame = self.scene.read()
        skin = self.skin.frame(frame.depth_m, rng, force_n=self.sensed_force_n(frame.depth_m))
        return PressResult(
            force_n,
            target,
            depth,
            frame.contactor,
            skin.pressure_pa,
            skin.signal_counts,
            skin.reading,
        )


def calibration_curve(
    part: Part,
    probe: Probe,
    forces_n: np.ndarray,
    taxel: int,
    cfg: SkinConfig | None = None,
    seed: int = 0,
) -> dict[str, np.ndarray]:
    """Force sweep: summed reading, active taxels and depth per force (noise-free, seeded gains).

    Returns arrays (F,): force_n, depth_m, target_depth_m, summed_signal_counts (reading minus
    baseline, summed), saturated (taxels at 65535), active (taxels with depth > 0),
    contact_radius_m and expected_active (taxels within that radius: the closed-form reference).
    """
    cfg = cfg or SkinConfig()
    skin = SkinInstance.create(
        part.layout.positions_m, cfg, np.random.default_rng(seed), part.sensor_faces
    )
    rig = ProbeRig(part, probe, taxel, skin)
    rows = [rig.press(float(f)) for f in forces_n]
    depth = np.array([r.depth_m for r in rows])
    return {
        "contact_radius_m": contact_radius_m(probe, depth),
        "expected_active": expected_active(part, taxel, probe, depth),
        "force_n": np.asarray(forces_n, dtype=float),
        "depth_m": depth,
        "target_depth_m": np.array([r.target_depth_m for r in rows]),
        "summed_signal_counts": np.array([r.signal_counts.sum() for r in rows]),
        "saturated": np.array([(r.reading == 65535).sum() for r in rows]),
        "active": np.array([(r.contactor >= 0).sum() for r in rows]),
    }


def central_taxel(part: Part) -> int:
    """The module-centre pad (iCub pad 3) nearest the middle of the tiling (flat (0, 0))."""
    pad3 = np.flatnonzero(part.layout.channel_ids % 12 == 3)
    return int(pad3[np.argmin(np.linalg.norm(part.flat_mm[pad3], axis=1))])


def contact_radius_m(probe: Probe, depth_m: np.ndarray) -> np.ndarray:
    """Closed-form contact radius (m) at depth (F,) m: sqrt(2Rδ - δ²) (sphere), r (cylinder),
    the half-diagonal (box); 0 where δ <= 0."""
    d = np.asarray(depth_m, dtype=float)
    if probe.shape == "sphere":
        a = np.sqrt(np.maximum(2 * probe.size_m[0] * d - d**2, 0.0))
    elif probe.shape == "cylinder":
        a = np.full_like(d, probe.size_m[0])
    else:
        a = np.full_like(d, float(np.hypot(*probe.size_m[:2])))
    return np.where(d > 0, a, 0.0)


def expected_active(part: Part, taxel: int, probe: Probe, depth_m: np.ndarray) -> np.ndarray:
    """Taxels (F,) within the closed-form contact radius of the pressed taxel, measured in its
    tangent plane (exact on a flat skin, a close approximation on gentle curvature)."""
    rel = part.layout.positions_m - part.layout.positions_m[taxel]
    n = part.layout.normals[taxel]
    lateral = np.linalg.norm(rel - np.outer(rel @ n, n), axis=1)
    radius = contact_radius_m(probe, depth_m)
    if probe.shape == "box":
        return np.array([np.sum(lateral < a) if a > 0 else 0 for a in radius])  # upper bound
    return np.array([np.sum(lateral < a) for a in radius])
