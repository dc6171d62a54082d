"""Hand poses of the interactions: joint targets with the subject's noise, wrist pitch, offsets.

Targets are degrees of flexion (positive = flexion, palmar abduction, cupping;
`sim.contactors.hand`). The finger servos are weak
(`sim.contactors.hand_kinematics.JOINT_TORQUE_NM`) and close only after the palm has landed
(`sim.episode.press.finger_fraction`), so targets beyond the link make fingers stop on it; the
finger spread alone is set in the air (`finger_spread`).

Modes (Albini & Cannata 2020, Fig. 6: whole hands, fingertips only, different pressures):
- ``wrap``: palm on a face with the MCP row on an edge, fingers around it (grasps; pushes whose
  fingers cross an edge drape round it, `_DRAPE`); ``hook`` for pulls;
- ``flat``: palm and straight fingers on a face long enough for them;
- ``fingertips``: a random subset of fingers, the wrist pitched so that only they touch;
- ``grip``: a grasp with the palm held clear of the skin, over the aim (the digits alone touch);
- ``palm``: fingers lifted; ``curled``: loose fist, knuckles and palm.

Every mode fans the fingers by the subject's habitual spread (`finger_spread`; held from before
the hand lands, `sim.contactors.spec.PressPlan.preshape`), so that fingers do not press parallel and
touching; the whole-hand modes also open the thumb (`thumb_spread`, held likewise).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.contactors import placement
from sim.contactors.hand_kinematics import FINGERS, JOINT_LIMITS_DEG, hand_geometry
from sim.contactors.subjects import FINGER_SPREAD_LIMIT_DEG, Subject
from sim.skin.parts import Part

_GRASP = {"mcp_flex": 70.0, "pip": 45.0, "dip": 20.0}  # beyond the edge: stop on the link
# The thumb opposed (Kapandji: palmar abduction and flexion of the first metacarpal), its targets
# beyond the link so that it closes on it: a large object needs the thumb's opposition (Mentzel
# et al., Handchir Mikrochir Plast Chir 43(3), 2011). Beside the fingers' 15 / -10 deg the thumb
# touched the skin in 51 % of grasps and carried 2 % of the digits' force; opposed, 74 % and 17 %.
_GRASP_THUMB = {"thumb_cmc_abd": 55.0, "thumb_cmc_flex": 25.0, "thumb_mcp": 20.0, "thumb_ip": 20.0}
_DRAPE = {"mcp_flex": 65.0, "pip": 40.0, "dip": 15.0}  # relaxed fingers round an edge
# On a face: the fingers close until their pads press it (targets 10-20 deg beyond a flat face,
# about half their torque; a finger past a rounded edge bends onto it). At 5 / 5 / 0 deg (was)
# they lay on the face without force and hovered over rounded edges: measured on the default
# forearm (160 hand prints, seeds 0-2 pooled) parts >= 5 in 55 -> 60 % of prints, area 7,338 ->
# 7,474 mm2, fingers with a mark of their own 0.286 -> 0.306 (mean).
_FLAT = {"mcp_flex": 20.0, "pip": 20.0, "dip": 10.0}
# The thumb of a hand pressed on the link closes palmarly until its pad meets the surface (40 deg
# is beyond a face or a rounded edge); in fingertip touches it stays clear (10 deg).
_FLAT_THUMB = {"thumb_cmc_abd": 40.0, "thumb_cmc_flex": -15.0, "thumb_mcp": 10.0, "thumb_ip": 10.0}
_TIPS_THUMB = {"thumb_cmc_abd": 10.0, "thumb_cmc_flex": -15.0, "thumb_mcp": 5.0, "thumb_ip": 5.0}
_HOOK = {"mcp_flex": 50.0, "pip": 50.0, "dip": 20.0}
_TIPS = {"mcp_flex": 20.0, "pip": 35.0, "dip": 10.0}  # with the wrist pitched: pads down
_LIFTED = {"mcp_flex": -25.0, "pip": 0.0, "dip": 0.0}
_CURLED = {"mcp_flex": 45.0, "pip": 60.0, "dip": 30.0}
TIPS_PITCH_DEG = (20.0, 35.0)  # wrist pitch of fingertip touches (fingertips down), degrees
FREE_VARIANTS = ("flat", "fingertips", "palm", "curled", "wrap")
FREE_PROBS = (0.3, 0.35, 0.05, 0.1, 0.2)  # fingertip touches are common in Fig. 6
# Palm cupping of a grasp: the 4th/5th CMC joints flex 10-15 / 20-30 deg (`sim.contactors.hand`); a
# power grasp uses most of it.
GRASP_ARCH_DEG = 20.0
# Finger fan: MCP abduction of each finger away from the middle one, in units of the spread.
FAN = {"index": 1.0, "middle": 0.0, "ring": 1.0, "pinkie": 2.0}
# The MCP flexion a finger reaches on the link, as a fraction of its target (targets lie beyond
# the link, `sim.contactors.interaction_poses`): measured at the kept frame of 100 hand prints
# (seed 0), grasps 28 of 70 deg, fingers draped round an edge 31 of 64, hooks 14 of 50 (medians).
# The ligaments limit the spread by the flexion reached: cut by the target's, a grasp's fingers
# kept a third of the habit (cos 70 deg) and their pads merged; measured on the default forearm
# (160 hand prints, seeds 0-2 pooled) fingers with a mark of their own 0.235 -> 0.286 (mean).
MCP_REACHED = 0.4
# Thumb spread: in a whole-hand touch the thumb opens radially (CMC radial abduction, negative
# `thumb_cmc_flex`) this far beyond its home, uniform per trial, up to the joint's published
# maximum, held from the air. In the real prints the thumb's pad lies 111 deg (median) from the
# finger pads about the palm centre and 156 mm from them (430 prints with palm, thumb and a finger
# boxed, ../shared/data/real_hands; 11 below 60 deg), at or beyond what a flat hand reaches with
# the thumb fully open (about 96 deg): people open the hand, thumb included, to the size of what
# they hold (Santello et al., J Neurosci 18(23), 1998). With the thumb at its home (and flexed
# across the palm in grasps) the default forearm's prints read 69 deg and 70 mm; the thumb's share
# of a grasp's digit force rose from 13.2 to 16.5 % (published estimate 17 %).
THUMB_SPREAD_DEG = (20.0, 35.0)
THUMB_SPREAD_MODES = ("grasp", "grip", "hook", "flat", "palm")  # not a fist nor fingertip touches


@dataclass(frozen=True)
class HandPose:
    """Joint targets (suffix -> rad), palm shift (m along the hand's x, from the aim to the palm
    centre), wrist pitch (rad, + = fingertips down) and the mode name."""

    targets_rad: dict[str, float]
    shift_m: float = 0.0
    pitch_rad: float = 0.0
    mode: str = "flat"
    preshape: tuple[str, ...] = ()  # suffixes held from the start (`PressPlan.preshape`)


def _limit_key(suffix: str) -> str:
    return suffix if suffix in JOINT_LIMITS_DEG else suffix.split("_", 1)[1]


def _fingers(targets: dict[str, float], fingers=FINGERS) -> dict[str, float]:
    return {f"{f}_{j}": v for f in fingers for j, v in targets.items()}


def _noisy(pose_deg: dict[str, float], sd_deg: float, rng: np.random.Generator) -> dict:
    """Joint suffix -> target (rad): pose plus N(0, sd) noise, clipped to the joint limits."""
    out = {}
    for suffix in sorted(pose_deg):
        lo, hi = JOINT_LIMITS_DEG[_limit_key(suffix)]
        out[suffix] = float(np.deg2rad(np.clip(pose_deg[suffix] + rng.normal(0, sd_deg), lo, hi)))
    return out


def finger_spread(
    subject: Subject, targets_rad: dict[str, float], rng: np.random.Generator
) -> dict[str, float]:
    """MCP abduction targets (suffix -> rad) fanning the fingers apart by this trial's spread.

    The spread is the subject's habit plus N(0, half their pose noise), clipped to
    `FINGER_SPREAD_LIMIT_DEG`; each finger turns `FAN` times it away from the middle finger, times
    the cosine of the MCP flexion it reaches on the link, `MCP_REACHED` of its target: the
    collateral ligaments tighten as the MCP flexes, so a finger bent 90 degrees cannot spread
    (Kapandji, The Physiology of the Joints, vol. 1); no finger beyond its MCP's abduction limit
    (the pinkie, twice the spread, stops at 20 degrees).
    """
    lo, hi = FINGER_SPREAD_LIMIT_DEG
    habit, noise = subject.finger_spread_deg, 0.5 * subject.pose_noise_deg
    spread = float(np.clip(habit + rng.normal(0.0, noise), lo, hi))
    limit = JOINT_LIMITS_DEG["mcp_abd"][1]
    out = {}
    for f in FINGERS:
        bend = max(float(np.cos(MCP_REACHED * targets_rad.get(f"{f}_mcp_flex", 0.0))), 0.0)
        out[f"{f}_mcp_abd"] = float(np.deg2rad(min(FAN[f] * spread * bend, limit)))
    return out


def thumb_spread(mode: str, rng: np.random.Generator) -> dict[str, float]:
    """Radial abduction target (suffix -> rad) opening the thumb `THUMB_SPREAD_DEG` beyond its
    home in the modes of `THUMB_SPREAD_MODES` (none in the others), within the joint's limit."""
    if mode not in THUMB_SPREAD_MODES:
        return {}
    lo, hi = THUMB_SPREAD_DEG
    limit = JOINT_LIMITS_DEG["thumb_cmc_flex"][0]
    return {"thumb_cmc_flex": float(np.deg2rad(max(-rng.uniform(lo, hi), limit)))}


def mcp_offset_m(subject: Subject) -> float:
    """Distance (m) along the hand's x from the palm centre to the middle finger's MCP."""
    geo = hand_geometry(subject.hand.length_m, subject.hand.breadth_m)
    return float(geo.mcp_m["middle"][0] - 0.3 * geo.length_m)


def fingertip_reach_m(subject: Subject, fingers: list[str]) -> float:
    """Mean distance (m) along hand x from the palm centre to the tips of ``fingers`` (straight)."""
    geo = hand_geometry(subject.hand.length_m, subject.hand.breadth_m)
    reach = [geo.mcp_m[f][0] + geo.lengths_m[f][1:].sum() for f in fingers]
    return float(np.mean(reach) - 0.3 * geo.length_m)


def _fingertips(subject: Subject, rng: np.random.Generator) -> tuple[dict, float, float]:
    """Pose (deg), shift (m) and pitch (rad) of a touch with 1-4 fingertips."""
    down = [str(f) for f in rng.choice(FINGERS, size=int(rng.integers(1, 5)), replace=False)]
    up = [f for f in FINGERS if f not in down]
    pose = {**_fingers(_TIPS, down), **_fingers(_LIFTED, up), **_TIPS_THUMB}
    pitch = np.deg2rad(rng.uniform(*TIPS_PITCH_DEG))
    return pose, -0.8 * fingertip_reach_m(subject, down), float(pitch)


def _mode_pose(mode: str, wrap_shift_m: float | None) -> tuple[dict, float]:
    """Pose (deg) and shift (m) of the palm-on-face modes."""
    # A grip (the palm held clear, `sim.contactors.interactions.PALM_CLEAR_P`) keeps the palm
    # over the aim: shifted to put the MCP row on an edge, as a grasp's, the digits closed round
    # it onto bare link. Measured on 581 hand prints (seed 1), the share of prints without a palm
    # showing all five digits: 0.27 shifted, 0.38 over the aim (real 0.83); a thumb flexed
    # further (MCP 55, IP 60 deg) touched no more often and took 22 % of a grasp's digit force.
    if mode in ("grasp", "grip"):
        pose = {**_fingers(_GRASP), **_GRASP_THUMB, "palm_arch": GRASP_ARCH_DEG}
        return pose, (wrap_shift_m or 0.0) if mode == "grasp" else 0.0
    if mode == "hook":
        return {**_fingers(_HOOK), **_FLAT_THUMB, "palm_arch": 5.0}, wrap_shift_m or 0.0
    if mode == "palm":
        return {**_fingers(_LIFTED), **_FLAT_THUMB}, 0.0
    if mode == "curled":
        return {**_fingers(_CURLED), **_GRASP_THUMB, "palm_arch": 5.0}, 0.0
    if wrap_shift_m is not None:  # flat hand whose fingers cross an edge: they drape round it
        return {**_fingers(_DRAPE), **_FLAT_THUMB, "palm_arch": 5.0}, wrap_shift_m
    return {**_fingers(_FLAT), **_FLAT_THUMB}, 0.0


def action_mode(action: str, rng: np.random.Generator) -> str:
    """Hand mode of ``action``: grasp, hook (pull), flat (pushes) or a drawn free variant."""
    if action.startswith("grasp"):
        return "grasp"
    if action == "pull":
        return "hook"
    if action == "free":
        variant = FREE_VARIANTS[int(rng.choice(len(FREE_VARIANTS), p=FREE_PROBS))]
        return "grasp" if variant == "wrap" else variant
    return "flat"


def finger_pose(
    mode: str, subject: Subject, rng: np.random.Generator, wrap_shift_m: float | None = None
) -> HandPose:
    """The `HandPose` of ``mode`` with the subject's noise; ``wrap_shift_m``: palm shift that puts
    the MCP row on the edge the fingers cross (None: no edge within the fingers' reach)."""
    pitch = 0.0
    if mode == "fingertips":
        pose, shift, pitch = _fingertips(subject, rng)
    else:
        pose, shift = _mode_pose(mode, wrap_shift_m)
    targets = _noisy(pose, subject.pose_noise_deg, rng)
    spread = finger_spread(subject, targets, rng) | thumb_spread(mode, rng)
    return HandPose(targets | spread, shift, pitch, mode, tuple(spread))


def hand_direction(part: Part, taxel: int, yaw_rad: float) -> np.ndarray:
    """(3,) unit tangent at ``taxel``: the hand's x (distal) yawed by ``yaw_rad`` from the link
    axis about the outward normal (the runner's skin frame, `sim.episode.runner.site_pose`)."""
    z = part.layout.normals[taxel]
    axis = placement.link_axis(part)
    x = axis - np.dot(axis, z) * z
    x /= np.linalg.norm(x)
    return np.cos(yaw_rad) * x + np.sin(yaw_rad) * np.cross(z, x)


def hand_offset_uv(part: Part, taxel: int, offset_m: float, yaw_rad: float) -> np.ndarray:
    """(2,) mm: flat-lattice displacement of a point ``offset_m`` along the hand's x (yawed by
    ``yaw_rad`` from the link axis) from ``taxel``, by the local Jacobian of the lattice."""
    if offset_m == 0.0:
        return np.zeros(2)
    d3 = offset_m * hand_direction(part, taxel, yaw_rad)
    duv, *_ = np.linalg.lstsq(placement.lattice_jacobian(part, taxel), d3, rcond=None)
    return duv
