"""The press scene: a part, a contactor on a 6-DoF force-limited root, and the press schedule.

`build_press_scene` composes the part (``fa_`` prefix, `sim.episode.scene.add_part`) and a contactor
(``c_`` prefix) attached under a static body ``press`` whose pose is the skin frame of the
episode (z along the outward normal, x along the link axis). The contactor's ``root`` gets six
joints — slides ``press_x/y/z`` in the skin frame, then hinges ``press_yaw`` (about the normal),
``press_tilt_x``, ``press_tilt_y`` — each driven by a position actuator whose force limit is set
per phase in `model.actuator_forcerange` (a model array: the compiled model is reused for every
episode of the same contactor, only `body_pos`/`body_quat` of ``press`` and the limits change).

Schedule (`root_schedule`, `schedule`; 100 Hz ticks precomputed per episode): approach = the
root target descends from `APPROACH_HEIGHT_M` to the skin point; load = it sinks
`PRESS_DEPTH_M` below while the normal force is capped at the plan's `force_n` (a force-limited
servo: the force ramps with the target, then saturates; a plan with a standoff stops that far
above the skin point instead and only the closing joints touch, `PressPlan.standoff_m`); hold =
the shear slides and the yaw hinge pull towards far targets capped at the plan's shear and
twist; release = back up.
Contactor joints (fingers) stay at 0 during the approach and go to their plan targets during the
load, torque-limited by the contactor's own actuators: a hand's palm lands first, then the
fingers close (fingers closing during the approach would meet the link before the palm and prop
it up). A hand's wrist (tilt hinges) is stiffer than an object's
(`HAND_TILT_KP`), so closing fingers cannot roll the palm off the face.

Several contactors press in one scene as several *drives*: contactor k > 0 is attached with the
prefix ``c<k>_`` under its own body ``press<k>``, on root joints ``press<k>_x`` ...; contactor 0
keeps the names above, so a one-contactor scene is the same model either way.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np

from sim.contactors.hand import set_hand_options
from sim.contactors.spec import ROOT, ContactorSpec, PressPlan
from sim.episode.scene import PART_PREFIX, add_part
from sim.skin.parts import Part
from sim.skin.readout import TaxelReadout

PREFIX = "c_"  # contactor elements in the scene (a non-empty attach prefix; MuJoCo logs otherwise)
ROOT_JOINTS = ("x", "y", "z", "yaw", "tilt_x", "tilt_y")
APPROACH_HEIGHT_M = 0.03  # start of the root above the skin point along the normal, m
PRESS_DEPTH_M = 0.04  # final root target below the skin point: force saturates before, m
SHEAR_TRAVEL_M = 0.03  # shear target offset: the slide force saturates at the plan's shear, m
TWIST_TRAVEL_RAD = 0.6  # twist target offset: the yaw torque saturates at the plan's twist
SLIDE_KP = 2000.0  # N/m: force F is reached at F / kp behind the target (20 N at 1 cm)
HOLD_FORCE_N = 20.0  # force limit of the tangential slides when they only hold position, N
YAW_KP, YAW_HOLD_NM = 20.0, 2.0  # N m/rad, N m
TILT_KP, TILT_LIMIT_NM = 6.0, 2.0  # compliant wrist: the contactor settles on the surface
# A hand's wrist is held by the arm: stiffer, so that closing fingers (1-3 N each at 5-10 cm)
# cannot roll the palm off the face (measured at 6 N m/rad: 10-20 deg, palm force -> 0).
HAND_TILT_KP, HAND_TILT_LIMIT_NM = 30.0, 6.0  # N m/rad, N m (wrist torques reach 5-10 N m)
ROOT_MASS_KG = 0.02  # root body mass, so a root made only of attached children is never massless


@dataclass(eq=False)
class Drive:
    """How one contactor of a press scene is driven: its root's actuators (6,) and qpos addresses
    (6,) (order `ROOT_JOINTS`), its joints' actuators (unprefixed joint name -> id), its press
    body, its wrist torque limit (N m), and the joint targets of the current plan (set by
    `reset`: actuator ids, targets in rad, and which are preshaped)."""

    root_act: np.ndarray
    root_qpos: np.ndarray
    joint_act: dict[str, int]
    press_body: int
    tilt_limit_nm: float = TILT_LIMIT_NM
    plan_act: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    plan_target: np.ndarray = field(default_factory=lambda: np.zeros(0))
    plan_preshape: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))


@dataclass(eq=False)
class PressScene:
    """One compiled press scene (reused across episodes of the same contactors).

    geom_label : (K,) int64 class of each readout contactor geom; geom_contactor : (K,) int64
    which contactor it belongs to; drives : one `Drive` per contactor; compiled_forcerange :
    (nu, 2) the actuators' force limits as compiled.
    """

    model: mujoco.MjModel
    data: mujoco.MjData
    readout: TaxelReadout
    geom_label: np.ndarray
    geom_contactor: np.ndarray
    drives: tuple[Drive, ...]
    compiled_forcerange: np.ndarray

    @property
    def joint_act(self) -> dict[str, int]:
        """The first contactor's joint actuators (unprefixed joint name -> id)."""
        return self.drives[0].joint_act


def prefix(k: int) -> str:
    """Attach prefix of contactor ``k`` in a press scene."""
    return PREFIX if k == 0 else f"c{k}_"


def press_name(k: int) -> str:
    """Name of contactor ``k``'s press body, and the stem of its root joints and actuators."""
    return "press" if k == 0 else f"press{k}"


def _add_root(spec: mujoco.MjSpec, k: int, tilt_kp: float = TILT_KP) -> None:
    """Six joints and force-limited position actuators on contactor ``k``'s attached root."""
    root = spec.body(prefix(k) + ROOT)
    root.explicitinertial, root.mass = True, ROOT_MASS_KG
    root.inertia = [1e-5, 1e-5, 1e-5]
    axes = np.eye(3)[[0, 1, 2, 2, 0, 1]]
    for j, (name, axis) in enumerate(zip(ROOT_JOINTS, axes, strict=True)):
        slide = j < 3
        kind = mujoco.mjtJoint.mjJNT_SLIDE if slide else mujoco.mjtJoint.mjJNT_HINGE
        joint = f"{press_name(k)}_{name}"
        root.add_joint(name=joint, type=kind, axis=axis, armature=0 if slide else 1e-3)
        kp = SLIDE_KP if slide else (YAW_KP if name == "yaw" else tilt_kp)
        act = spec.add_actuator(
            name=joint,
            target=joint,
            trntype=mujoco.mjtTrn.mjTRN_JOINT,
            forcelimited=mujoco.mjtLimited.mjLIMITED_TRUE,
            forcerange=[-1.0, 1.0],
        )
        act.set_to_position(kp=kp, dampratio=1.0)


def scene_spec(
    part: Part,
    contactors: ContactorSpec | Sequence[ContactorSpec],
    timestep_s: float,
    solver_iterations: int = 100,
    link_file: str | None = None,
    skin_file: str | None = None,
) -> mujoco.MjSpec:
    """The press scene spec: options (time step, s; the solver's iteration cap), the part (its
    link and sensor meshes read from ``link_file`` / ``skin_file`` when given,
    `sim.episode.scene.link_mesh_file` / `skin_mesh_file`), each contactor under its press
    body."""
    contactors = _as_list(contactors)
    spec = mujoco.MjSpec()
    spec.modelname = f"{part.name}_press_{'_'.join(c.name for c in contactors)}"
    set_hand_options(spec, timestep_s)
    spec.option.iterations = int(solver_iterations)
    spec.option.gravity = [0.0, 0.0, 0.0]  # forces are the commanded ones
    add_part(spec, part, link_file=link_file, skin_file=skin_file)
    for k, c in enumerate(contactors):
        press = spec.worldbody.add_body(name=press_name(k))
        spec.attach(c.spec.copy(), frame=press.add_frame(), prefix=prefix(k))
        _add_root(spec, k, HAND_TILT_KP if c.kind == "hand" else TILT_KP)
    return spec


def _as_list(contactors: ContactorSpec | Sequence[ContactorSpec]) -> list[ContactorSpec]:
    return [contactors] if isinstance(contactors, ContactorSpec) else list(contactors)


def build_press_scene(
    part: Part,
    contactors: ContactorSpec | Sequence[ContactorSpec],
    timestep_s: float,
    solver_iterations: int = 100,
    link_file: str | None = None,
    skin_file: str | None = None,
) -> PressScene:
    """Compile the press scene of ``contactors`` (one or several) on ``part`` and index its
    named elements."""
    contactors = _as_list(contactors)
    model = scene_spec(
        part, contactors, timestep_s, solver_iterations, link_file, skin_file
    ).compile()
    names = [(k, n) for k, c in enumerate(contactors) for n in sorted(c.geom_labels)]
    readout = TaxelReadout(
        model, f"{PART_PREFIX}tactile", f"{PART_PREFIX}skin", [prefix(k) + n for k, n in names]
    )
    act = {model.actuator(i).name: i for i in range(model.nu)}
    drives = []
    for k, c in enumerate(contactors):
        stem, pre = press_name(k), prefix(k)
        joints = {n[len(pre) :]: i for n, i in act.items() if n.startswith(pre)}
        root = np.array([act[f"{stem}_{n}"] for n in ROOT_JOINTS])
        qadr = [model.jnt_qposadr[model.joint(f"{stem}_{n}").id] for n in ROOT_JOINTS]
        tilt = HAND_TILT_LIMIT_NM if c.kind == "hand" else TILT_LIMIT_NM
        drives.append(Drive(root, np.asarray(qadr), joints, model.body(stem).id, tilt))
    return PressScene(
        model,
        mujoco.MjData(model),
        readout,
        np.array([contactors[k].geom_labels[n] for k, n in names], dtype=np.int64),
        np.array([k for k, _ in names], dtype=np.int64),
        tuple(drives),
        model.actuator_forcerange.copy(),
    )


def _ramp(t: np.ndarray, t0: float, t1: float) -> np.ndarray:
    """0 before t0, 1 after t1, smoothstep in between; t : (T,) s."""
    t = np.asarray(t, dtype=float)
    if t1 <= t0:
        return (t >= t1).astype(float)
    s = np.clip((t - t0) / (t1 - t0), 0.0, 1.0)
    return s * s * (3.0 - 2.0 * s)


def root_schedule(plan: PressPlan, times_s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Targets (T, 6) (m, rad) and force limits (T, 6) (N, N m) of the root at times (T,) s."""
    t = np.asarray(times_s, dtype=float)
    a, lo, h, _ = np.cumsum(plan.durations_s)
    sink = _ramp(t, a, lo) - _ramp(t, h, plan.total_s)
    hold = _ramp(t, lo, lo + 0.5 * plan.durations_s[2]) * (t < h)
    up = 1.0 - _ramp(t, 0.0, a) + _ramp(t, h, plan.total_s)
    if plan.standoff_m > 0:  # held off the skin: no sink, the closing joints grip
        sink = np.zeros_like(t)
        z = plan.standoff_m + (APPROACH_HEIGHT_M - plan.standoff_m) * up
    else:
        z = APPROACH_HEIGHT_M * up
    shear, twist = np.asarray(plan.shear_n, dtype=float), plan.twist_nm
    target = np.column_stack(
        [
            SHEAR_TRAVEL_M * np.sign(shear[0]) * hold,
            SHEAR_TRAVEL_M * np.sign(shear[1]) * hold,
            z - PRESS_DEPTH_M * sink,
            plan.yaw_rad + TWIST_TRAVEL_RAD * np.sign(twist) * hold,
            np.broadcast_to(plan.tilt_rad, (t.size, 2)),
        ]
    )
    holding = hold[:, None] > 0
    lim_xy = np.where(holding & (shear != 0), np.abs(shear), HOLD_FORCE_N)
    lim_yaw = np.where(holding[:, 0] & (twist != 0), abs(twist), YAW_HOLD_NM)
    fixed = np.broadcast_to([plan.force_n], (t.size, 1))
    limit = np.column_stack([lim_xy, fixed, lim_yaw, np.full((t.size, 2), TILT_LIMIT_NM)])
    return target, limit


def root_controls(plan: PressPlan, t: float) -> tuple[np.ndarray, np.ndarray]:
    """Targets (6,) (m, rad) and force limits (6,) (N, N m) of the root at time ``t`` (s)."""
    target, limit = root_schedule(plan, np.array([t]))
    return target[0], limit[0]


def finger_fraction(plan: PressPlan, t: np.ndarray | float) -> np.ndarray:
    """How far the contactor joints are from 0 (1 = plan targets) at time(s) ``t`` (s): they close
    during the load phase, after the root has brought the contactor (a palm) onto the skin."""
    a, lo, h, _ = np.cumsum(plan.durations_s)
    return _ramp(t, a, lo) - _ramp(t, h, plan.total_s)


@dataclass(frozen=True)
class Schedule:
    """Controls at T ticks: ``ctrl`` (T, nu) and ``forcerange`` (T, nu, 2), the whole rows of
    `mjData.ctrl` and `mjModel.actuator_forcerange` at each tick (root targets, m and rad, and
    force limits, N and N m; the contactor joints' targets, rad; every other actuator as
    compiled), so that a tick is two copies."""

    ctrl: np.ndarray
    forcerange: np.ndarray


def schedule(
    scene: PressScene, plans: PressPlan | Sequence[PressPlan], times_s: np.ndarray
) -> Schedule:
    """The controls of the plans (one per drive) at times (T,) s (after `reset` with them)."""
    plans = [plans] if isinstance(plans, PressPlan) else list(plans)
    ctrl = np.zeros((len(times_s), scene.model.nu))
    forcerange = np.repeat(scene.compiled_forcerange[None], len(times_s), axis=0)
    for drive, plan in zip(scene.drives, plans, strict=True):
        target, limit = root_schedule(plan, times_s)
        limit[:, 4:] = drive.tilt_limit_nm
        frac = finger_fraction(plan, times_s)[:, None]
        frac = np.where(drive.plan_preshape[None, :], 1.0, frac)
        ctrl[:, drive.root_act] = target
        ctrl[:, drive.plan_act] = frac * drive.plan_target[None, :]
        forcerange[:, drive.root_act, 0] = -limit
        forcerange[:, drive.root_act, 1] = limit
    return Schedule(ctrl, forcerange)


def apply_tick(scene: PressScene, sched: Schedule, i: int) -> None:
    """Write tick ``i`` of ``sched`` into ctrl and the actuators' force limits."""
    scene.data.ctrl[:] = sched.ctrl[i]
    scene.model.actuator_forcerange[:] = sched.forcerange[i]


def apply_controls(scene: PressScene, plans: PressPlan | Sequence[PressPlan], t: float) -> None:
    """Write the schedule at time ``t`` (s) into ctrl and the root force limits (after `reset`
    with the same plans, which caches their joint targets on the scene)."""
    apply_tick(scene, schedule(scene, plans, np.array([t])), 0)


def reset(
    scene: PressScene,
    plans: PressPlan | Sequence[PressPlan],
    pos_m: np.ndarray | Sequence[np.ndarray],
    quat: np.ndarray | Sequence[np.ndarray],
) -> None:
    """Place each press body at its skin frame (pos (3,) m, quat (4,) w x y z; one of each per
    plan when there are several) and start the episode."""
    single = isinstance(plans, PressPlan)
    plans = [plans] if single else list(plans)
    poses = [(pos_m, quat)] if single else list(zip(pos_m, quat, strict=True))
    m, d = scene.model, scene.data
    for drive, (pos, q) in zip(scene.drives, poses, strict=True):
        m.body_pos[drive.press_body], m.body_quat[drive.press_body] = pos, q
    mujoco.mj_resetData(m, d)
    for drive, plan in zip(scene.drives, plans, strict=True):
        names = list(plan.joint_targets)
        drive.plan_act = np.array([drive.joint_act[n] for n in names], dtype=np.int64)
        drive.plan_target = np.array([plan.joint_targets[n] for n in names], dtype=float)
        drive.plan_preshape = np.array([n in plan.preshape for n in names], dtype=bool)
        target, _ = root_controls(plan, 0.0)
        d.qpos[drive.root_qpos] = target
        # preshaped joints start at their targets: the hand arrives already shaped
        held = drive.plan_act[drive.plan_preshape]
        d.qpos[m.jnt_qposadr[m.actuator_trnid[held, 0]]] = drive.plan_target[drive.plan_preshape]
    apply_controls(scene, plans, 0.0)
