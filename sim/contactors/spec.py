"""What presses the skin and how: `ContactorSpec`, `PressPlan` and the interaction vocabulary.

Every contactor (hand, object, body part) is a `ContactorSpec` (a MuJoCo spec whose root body is
named ``root``, has no joints and whose ``+z`` points away from the skin) pressed by the episode
runner (`sim.episode.runner`) according to a `PressPlan`. Hands and non-hands differ only in the
spec and the plan. `sphere_contactor` is the simplest contactor: a rigid sphere used as a probe in
tests and calibration (its active taxels have a closed form).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco

from tactile.errors import ConfigError

ACTIONS: tuple[str, ...] = (
    "grasp",
    "grasp_twist_cw",
    "grasp_twist_ccw",
    "push_left",
    "push_right",
    "push_away",
    "pull",
    "free",
)
OPERATOR_POSITIONS: tuple[str, ...] = ("front", "side", "free")
KINDS: tuple[str, ...] = ("hand", "object", "body")
ROOT = "root"  # name of a contactor's root body


@dataclass(frozen=True, eq=False)
class ContactorSpec:
    """A contactor ready to be attached by the runner (see docs/DESIGN.md).

    spec : its root body ``root`` has no joints; its z axis points away from the skin (press -z).
    geom_labels : collision geom name (unprefixed, as in ``spec``) -> class (1..6 hand, 0 other).
    max_penetration_m : a deeper taxel reading than this fails the episode (tissue allowance).
    """

    spec: mujoco.MjSpec
    geom_labels: dict[str, int]
    kind: str
    name: str
    instance_id: int = -1
    subject_id: int = -1
    description: dict = field(default_factory=dict)
    max_penetration_m: float = 0.01

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ConfigError(f"ContactorSpec.kind={self.kind!r} unknown; choose one of {KINDS}")
        if not self.geom_labels:
            raise ConfigError(f"ContactorSpec {self.name!r} has no collision geoms in geom_labels")
        if not self.max_penetration_m > 0:
            raise ConfigError(f"ContactorSpec.max_penetration_m={self.max_penetration_m} <= 0")


@dataclass(frozen=True)
class PressPlan:
    """How one episode presses (see docs/DESIGN.md). Angles rad, forces N, torques N m, times s.

    site_uv : (u, v) in the part's flat lattice (``Part.flat_mm``), mm; None = runner draws one.
    shear_n : (along the link axis, around it) tangential force limits while holding.
    joint_targets : contactor joint name (unprefixed) -> target (rad) reached under torque limits.
    preshape : names in ``joint_targets`` held at their targets from the start (the shape a hand
        takes in the air, such as its finger spread); the others close after the palm lands.
    standoff_m : 0 = the root sinks onto the skin and presses (`sim.episode.press`); > 0 = it
        is held this far above the skin point, so that only the joints closing on the link touch
        (a hand gripping with its digits, the palm clear), m.
    """

    site_uv: tuple[float, float] | None = None
    yaw_rad: float = 0.0
    tilt_rad: tuple[float, float] = (0.0, 0.0)
    force_n: float = 5.0
    shear_n: tuple[float, float] = (0.0, 0.0)
    twist_nm: float = 0.0
    joint_targets: dict[str, float] = field(default_factory=dict)
    preshape: tuple[str, ...] = ()
    durations_s: tuple[float, float, float, float] = (0.2, 0.3, 0.3, 0.2)
    action: int = -1
    operator_position: int = -1
    standoff_m: float = 0.0

    def __post_init__(self) -> None:
        if not self.force_n > 0:
            raise ConfigError(f"PressPlan.force_n={self.force_n!r} must be > 0 N")
        if not 0.0 <= self.standoff_m < 0.03:
            raise ConfigError(
                f"PressPlan.standoff_m={self.standoff_m!r}: give 0 (press) up to 0.03 m"
            )
        stray = sorted(set(self.preshape) - set(self.joint_targets))
        if stray:
            raise ConfigError(
                f"PressPlan.preshape names {stray} that have no joint_targets; "
                "give every preshape joint a target"
            )
        if len(self.durations_s) != 4 or min(self.durations_s) < 0:
            raise ConfigError(f"PressPlan.durations_s={self.durations_s}: 4 values >= 0 needed")
        if not -1 <= self.action < len(ACTIONS):
            raise ConfigError(f"PressPlan.action={self.action}; allowed -1..{len(ACTIONS) - 1}")
        if not -1 <= self.operator_position < len(OPERATOR_POSITIONS):
            raise ConfigError(f"PressPlan.operator_position={self.operator_position}; -1..2")

    @property
    def total_s(self) -> float:
        """Episode length (approach + load + hold + release), s."""
        return float(sum(self.durations_s))


def sphere_contactor(
    radius_m: float = 0.01, mass_kg: float = 0.05, label: int = 0, instance_id: int = 0
) -> ContactorSpec:
    """A rigid sphere whose lowest point is the root origin (it touches the skin first there)."""
    if not radius_m > 0:
        raise ConfigError(f"sphere_contactor: radius_m={radius_m} must be > 0")
    spec = mujoco.MjSpec()
    spec.modelname = "sphere"
    root = spec.worldbody.add_body(name=ROOT)
    root.add_geom(
        name="sphere",
        type=mujoco.mjtGeom.mjGEOM_SPHERE,
        size=[radius_m, 0, 0],
        pos=[0, 0, radius_m],
        mass=mass_kg,
        priority=1,
        rgba=[0.9, 0.5, 0.2, 1],
    )
    desc = {"type": "sphere", "radius_m": radius_m, "mass_kg": mass_kg}
    return ContactorSpec(
        spec,
        {"sphere": label},
        "object",
        "sphere",
        instance_id=instance_id,
        description=desc,
        max_penetration_m=radius_m,
    )
