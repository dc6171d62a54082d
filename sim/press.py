"""The press scene: a part, a contactor on a 6-DoF force-limited root, and the press schedule.

`build_press_scene` composes the part (``fa_`` prefix, `sim.scene.add_part`) and a contactor
(``c_`` prefix) attached under a static body ``press`` whose pose is the skin frame of the
episode (z along the outward normal, x along the link axis). The contactor's ``root`` gets six
joints — slides ``press_x/y/z`` in the skin frame, then hinges ``press_yaw`` (about the normal),
``press_tilt_x``, ``press_tilt_y`` — each driven by a position actuator whose force limit is set
per phase in `model.actuator_forcerange` (a model array: the compiled model is reused for every
episode of the same contactor, only `body_pos`/`body_quat` of ``press`` and the limits change).

Schedule (`root_schedule`, `schedule`; 100 Hz ticks precomputed per episode): approach = the
root target descends from `APPROACH_HEIGHT_M` to the skin point; load = it sinks
`PRESS_DEPTH_M` below while the normal force is capped at the plan's `force_n` (a force-limited
servo: the force ramps with the target, then saturates); hold = the shear slides and the yaw
hinge pull towards far targets capped at the plan's shear and twist; release = back up.
Contactor joints (fingers) stay at 0 during the approach and go to their plan targets during the
load, torque-limited by the contactor's own actuators: a hand's palm lands first, then the
fingers close (fingers closing during the approach would meet the link before the palm and prop
it up). A hand's wrist (tilt hinges) is stiffer than an object's
(`HAND_TILT_KP`), so closing fingers cannot roll the palm off the face.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import mujoco
import numpy as np

from sim.contactors import ROOT, ContactorSpec, PressPlan
from sim.hand import set_hand_options
from sim.parts import Part
from sim.readout import TaxelReadout
from sim.scene import PART_PREFIX, add_part

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
class PressScene:
    """One compiled press scene (reused across episodes of the same contactor).

    geom_label : (K,) int64 class of each readout contactor geom; root_act, root_qpos : (6,) int
    actuator ids and qpos addresses of the root joints (order `ROOT_JOINTS`); joint_act :
    contactor joint name (unprefixed) -> its actuator id.
    """

    model: mujoco.MjModel
    data: mujoco.MjData
    readout: TaxelReadout
    geom_label: np.ndarray
    root_act: np.ndarray
    root_qpos: np.ndarray
    joint_act: dict[str, int]
    press_body: int
    tilt_limit_nm: float = TILT_LIMIT_NM
    plan_act: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))  # set by reset
    plan_target: np.ndarray = field(default_factory=lambda: np.zeros(0))  # rad, set by reset
    plan_preshape: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))  # set by reset


def _add_root(spec: mujoco.MjSpec, tilt_kp: float = TILT_KP) -> None:
    """Six joints and force-limited position actuators on the attached contactor root."""
    root = spec.body(PREFIX + ROOT)
    root.explicitinertial, root.mass = True, ROOT_MASS_KG
    root.inertia = [1e-5, 1e-5, 1e-5]
    axes = np.eye(3)[[0, 1, 2, 2, 0, 1]]
    for k, (name, axis) in enumerate(zip(ROOT_JOINTS, axes, strict=True)):
        slide = k < 3
        kind = mujoco.mjtJoint.mjJNT_SLIDE if slide else mujoco.mjtJoint.mjJNT_HINGE
        root.add_joint(name=f"press_{name}", type=kind, axis=axis, armature=0 if slide else 1e-3)
        kp = SLIDE_KP if slide else (YAW_KP if name == "yaw" else tilt_kp)
        act = spec.add_actuator(
            name=f"press_{name}",
            target=f"press_{name}",
            trntype=mujoco.mjtTrn.mjTRN_JOINT,
            forcelimited=mujoco.mjtLimited.mjLIMITED_TRUE,
            forcerange=[-1.0, 1.0],
        )
        act.set_to_position(kp=kp, dampratio=1.0)


def scene_spec(
    part: Part, contactor: ContactorSpec, timestep_s: float, solver_iterations: int = 100
) -> mujoco.MjSpec:
    """The press scene spec: options (time step, s; the solver's iteration cap), the part, the
    contactor under the ``press`` body."""
    spec = mujoco.MjSpec()
    spec.modelname = f"{part.name}_press_{contactor.name}"
    set_hand_options(spec, timestep_s)
    spec.option.iterations = int(solver_iterations)
    spec.option.gravity = [0.0, 0.0, 0.0]  # forces are the commanded ones
    add_part(spec, part)
    press = spec.worldbody.add_body(name="press")
    spec.attach(contactor.spec.copy(), frame=press.add_frame(), prefix=PREFIX)
    _add_root(spec, HAND_TILT_KP if contactor.kind == "hand" else TILT_KP)
    return spec


def build_press_scene(
    part: Part, contactor: ContactorSpec, timestep_s: float, solver_iterations: int = 100
) -> PressScene:
    """Compile the press scene of ``contactor`` on ``part`` and index its named elements."""
    model = scene_spec(part, contactor, timestep_s, solver_iterations).compile()
    names = sorted(contactor.geom_labels)
    readout = TaxelReadout(
        model, f"{PART_PREFIX}tactile", f"{PART_PREFIX}skin", [PREFIX + n for n in names]
    )
    act = {model.actuator(i).name: i for i in range(model.nu)}
    joint_act = {n[len(PREFIX) :]: i for n, i in act.items() if n.startswith(PREFIX)}
    root_act = np.array([act[f"press_{n}"] for n in ROOT_JOINTS])
    qadr = [model.jnt_qposadr[model.joint(f"press_{n}").id] for n in ROOT_JOINTS]
    return PressScene(
        model,
        mujoco.MjData(model),
        readout,
        np.array([contactor.geom_labels[n] for n in names], dtype=np.int64),
        root_act,
        np.asarray(qadr),
        joint_act,
        model.body("press").id,
        HAND_TILT_LIMIT_NM if contactor.kind == "hand" else TILT_LIMIT_NM,
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
    z = APPROACH_HEIGHT_M * (1.0 - _ramp(t, 0.0, a) + _ramp(t, h, plan.total_s))
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
    """Controls at T ticks: root targets (T, 6), root force limits (T, 6), joint ctrl (T, J)."""

    root_target: np.ndarray
    root_limit: np.ndarray
    joint_ctrl: np.ndarray


def schedule(scene: PressScene, plan: PressPlan, times_s: np.ndarray) -> Schedule:
    """The controls of ``plan`` at times (T,) s (after `reset` with the same plan)."""
    target, limit = root_schedule(plan, times_s)
    limit[:, 4:] = scene.tilt_limit_nm
    frac = np.where(scene.plan_preshape[None, :], 1.0, finger_fraction(plan, times_s)[:, None])
    return Schedule(target, limit, frac * scene.plan_target[None, :])


def apply_tick(scene: PressScene, sched: Schedule, i: int) -> None:
    """Write tick ``i`` of ``sched`` into ctrl and the root force limits."""
    scene.data.ctrl[scene.root_act] = sched.root_target[i]
    scene.model.actuator_forcerange[scene.root_act, 0] = -sched.root_limit[i]
    scene.model.actuator_forcerange[scene.root_act, 1] = sched.root_limit[i]
    scene.data.ctrl[scene.plan_act] = sched.joint_ctrl[i]


def apply_controls(scene: PressScene, plan: PressPlan, t: float) -> None:
    """Write the schedule at time ``t`` (s) into ctrl and the root force limits (after `reset`
    with the same plan, which caches its joint targets on the scene)."""
    apply_tick(scene, schedule(scene, plan, np.array([t])), 0)


def reset(scene: PressScene, plan: PressPlan, pos_m: np.ndarray, quat: np.ndarray) -> None:
    """Place ``press`` at the skin frame (pos (3,), quat (4,) w x y z) and start the episode."""
    m, d = scene.model, scene.data
    m.body_pos[scene.press_body], m.body_quat[scene.press_body] = pos_m, quat
    mujoco.mj_resetData(m, d)
    names = list(plan.joint_targets)
    scene.plan_act = np.array([scene.joint_act[n] for n in names], dtype=np.int64)
    scene.plan_target = np.array([plan.joint_targets[n] for n in names], dtype=float)
    scene.plan_preshape = np.array([n in plan.preshape for n in names], dtype=bool)
    target, _ = root_controls(plan, 0.0)
    d.qpos[scene.root_qpos] = target
    # preshaped joints start at their targets: the hand arrives already shaped
    held = scene.plan_act[scene.plan_preshape]
    d.qpos[m.jnt_qposadr[m.actuator_trnid[held, 0]]] = scene.plan_target[scene.plan_preshape]
    apply_controls(scene, plan, 0.0)
