"""Press modes shared by objects and body parts: force, tilt and shear ranges and durations, and
the `PressPlan` drawn from them."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.contactors.primitives import unif
from sim.contactors.spec import PressPlan


@dataclass(frozen=True)
class PressMode:
    """A way of pressing: force (N), tilt (rad), shear (N) ranges and phase durations (s)."""

    force_n: tuple[float, float]
    tilt_rad: tuple[float, float]
    shear_n: tuple[float, float] = (0.0, 0.0)
    durations_s: tuple[float, float, float, float] = (0.2, 0.3, 0.3, 0.2)


def plan_from_mode(rng: np.random.Generator, mode: PressMode) -> PressPlan:
    """A `PressPlan` drawn from ``mode``: yaw uniform, tilt in a random direction, shear along a
    random tangent; the runner draws the skin point (``site_uv=None``)."""
    tilt, azimuth = unif(rng, *mode.tilt_rad), unif(rng, -np.pi, np.pi)
    shear, heading = unif(rng, *mode.shear_n), unif(rng, -np.pi, np.pi)
    return PressPlan(
        yaw_rad=unif(rng, -np.pi, np.pi),
        tilt_rad=(tilt * float(np.cos(azimuth)), tilt * float(np.sin(azimuth))),
        force_n=unif(rng, *mode.force_n, log=True),
        shear_n=(shear * float(np.cos(heading)), shear * float(np.sin(heading))),
        durations_s=mode.durations_s,
    )


def draw_mode(rng: np.random.Generator, modes: dict[str, tuple[float, PressMode]]) -> str:
    """One mode name, drawn with the table's probabilities."""
    names = list(modes)
    p = np.array([modes[n][0] for n in names])
    return names[int(rng.choice(len(names), p=p / p.sum()))]
