"""Hand interactions of Albini & Cannata (IJRR 2020) as `PressPlan`s for the episode runner.

Seven actions (grasp, grasp + twist cw/ccw, push left/right/away, pull) from two operator
positions, plus free interactions. Everything is expressed in the skin frame of the press site
(x along the link axis, z the outward normal) and the hand frame (x distal, y towards the thumb
of a right hand, palm facing the skin); ``yaw`` turns the hand's x away from the link axis.

Operator positions. In front of the link, the operator's forearm is roughly perpendicular to the
link, so pushes and pulls lay the fingers *across* it (yaw 90 deg +- the subject's habit). At the
side, the operator's forearm runs roughly along the link: pushes and pulls are done with the
fingers *along* it (yaw 180 deg). A grasp from either position holds the link obliquely across
the palm (`GRASP_YAW_DEG`), as a power grasp holds a cylinder (Napier, J Bone Joint Surg 38-B,
1956). The operator stands where the paper's people stood (`INDEX_END`): the index finger nearer
the link's base (z = 0), so a right hand and a left one yaw opposite ways. Measured on the real
prints (../shared/data/real_hands, fold 1): index to little finger points along the map's
columns (+-45 deg) in 71 % of prints and the other way in 15 %, thumb to fingers across them in
96 %; with either side drawn at random (and fingers turned towards more skin) the default set
read 34 % and 34 % (600 hand prints, seed 3), with the stance 70 % and 4 %. Free touches come
from anywhere (fingers towards more skin).

Directions (the operator's view, palm down): push away = towards the fingertips, pull = towards
the wrist (fingers hooked), push left / right = towards the operator's left / right (the hand's
+-y in the yawed skin frame: the thumb side of a right hand, the little finger of a left).
Twist cw = negative torque about the
outward normal (clockwise seen from above the hand).

Forces (N, before the subject's `force_scale`, log-uniform so one pose meets several pressures):
10-40 N normal force for pushes, 16-50 N for grasps, 4-30 N for free touches. Deliberate
pushes and grasps of a robot link to move it are firm: hand-guiding forces in physical
human-robot interaction are typically 10-50 N, comfortable one-handed push/pull forces on a
handle are several tens of newtons (ergonomics tables, e.g. Snook & Ciriello), power-grip forces
to hold an object are 20-50 N (a fraction of the 300-500 N maximal grip), and ISO/TS 15066
puts the quasi-static limit for the hand at 140 N; gentle and social touches are a few newtons
(the free range's low end). Shear is 25-60 % of the normal force (below the friction of skin,
mu ~ 0.8), twist 0.2-0.8 N m. (Lower ranges, 8-25 / 5-20 / 2-15 N, light a median of 38 active
taxels per contact instead of these ranges' 43.) Finger torques are
the hand's joint actuators (torque-limited): targets beyond the link make fingers close until
they meet it.

Placement (fair between classes): the aim is drawn by `sim.contactors.placement.draw_aim_taxel`, the
same draw the runner makes for non-hand contactors. The hand is then arranged around the aim:
the palm centre on the aim, shifted along the hand so that the MCP row lies on the edge the
fingers cross (`wrap_shift_m`; grasps, pulls and pushes across a face; at most
`MAX_GRASP_SHIFT_M`, `BAND_MAX_SHIFT_M` on a part with an aim band), or back for fingertip
touches. Measured on the previous default skin over 1,710 hand and 1,820 non-hand prints:
pressure-weighted contact centroids on the lattice do not differ along u / v (two-sample KS
p = 0.11 / 0.13). On the default skin (1,400 samples, seed 5) the hands' centroids lie 10 mm
further around (medians -9.7 / 0.9 mm, p < 0.01) and 7 mm further along (-10.2 / -2.8, p = 0.02)
than the non-hands': the operator stands on one side, and hands reach out from the palm. Hands
reach nearer the map's border on both skins.
"""

from __future__ import annotations

from functools import lru_cache

import mujoco
import numpy as np

from sim.contactors.hand import HAND_PARTS, TISSUE_RATIO, build_hand_spec, geom_parts
from sim.contactors.hand_kinematics import hand_geometry
from sim.contactors.interaction_poses import (
    action_mode,
    finger_pose,
    hand_direction,
    hand_offset_uv,
    mcp_offset_m,
)
from sim.contactors.placement import draw_aim_taxel, edge_distance_m
from sim.contactors.spec import ACTIONS, OPERATOR_POSITIONS, ROOT, ContactorSpec, PressPlan
from sim.contactors.subjects import Subject
from sim.skin.parts import Part

HAND_PREFIX = "h_"  # attach prefix of the hand inside the contactor spec
ROOT_JOINT_SUFFIXES = ("root_x", "root_y", "root_z", "root_rx", "root_ry", "root_rz")
FORCE_RANGE_N = {"grasp": (16.0, 50.0), "push": (10.0, 40.0), "free": (4.0, 30.0)}
SHEAR_FRACTION = (0.25, 0.6)  # shear / normal force (below the friction of skin)
TWIST_RANGE_NM = (0.2, 0.8)
DURATIONS_S = (0.15, 0.25, 0.3, 0.2)  # approach, load, hold, release (nominal), s
INDEX_END = 1.0  # +1: a right hand yaws +90 deg in front (index nearer z = 0); -1: the mirror
# Yaw of every grasp (deg): the link lies obliquely across the palm, the fingers wrap the far edge
# diagonally and the thumb the near one. Measured on the default set (1,710 hand prints) against
# the real folds 1 / 2 (../shared/data/real_hands), front grasps across the link (yaw 90) -> all
# grasps at this yaw: palm to fingers -1 [IQR -48, 26] -> -28 [-55, 16] deg (real -35 [-59, -21]
# / -39 [-58, -24]); a grasp's thumb box 84 -> 53 mm from the map's top edge (real prints 41 /
# 38); the middle finger's box 72 -> 80 mm from the palm's (real 82 / 83); blobs per print 4 [3,
# 5] -> 5 [3, 5] (real 6 [4, 7] / 5 [4, 7]); the preset SegNet's real part localisation 69.6 /
# 68.1 -> 71.6 / 70.8 %. The fingers' strengths were refitted to it
# (`sim.contactors.hand_kinematics.DIGIT_STRENGTH`).
GRASP_YAW_DEG = 135.0
YAW_SD_DEG = 10.0  # trial-to-trial spread of the hand's yaw around the operator's nominal
TILT_SD_DEG = 4.0
TOWARD_SKIN_P = 0.85  # free touches: probability that the fingers point towards more skin
MAX_GRASP_SHIFT_M = 0.05  # largest palm shift from the aim for a grasp, m
# On a part with an aim band (`sim.skin.parts.Part.aim_band_mm`, the default skin) the palm moves
# at most this far towards the edge: the skin ends a little past it, and a palm shifted 50 mm
# there wrapped the fingers off it. Measured on the default skin (400 hand prints, seed 3; real
# 93-96 % each): digits boxed in 63-79 % (50 mm), 66-84 % (25 mm), 65-86 % with the palm on the
# aim; grasp force shares of the four fingers (240 grasps, seed 11; Li 2002: 32.2 / 32.6 / 23.5
# / 11.7) 33.5 / 31.8 / 23.4 / 11.4 at 50 mm, 30.5 / 34.4 / 24.9 / 10.2 at 25 mm, 28.7 / 37.7 /
# 24.9 / 8.7 on the aim (middle above its range), and the palm's share of a push 64, 59, 52 %.
BAND_MAX_SHIFT_M = 0.025
# The digits alone. In the real folds (../shared/data/real_hands) 212 of 684 hand prints (31 %)
# have no palm box, and 83 % of those show all five digits, laid out as in whole-hand prints
# (thumb 126 mm from the fingers, index to little finger 90 mm; with a palm 121 and 88): the
# same open grasp with the palm clear of the skin. Without this, 2.9 % of generated hand prints
# lacked a palm (581 prints, seed 1). A grasp, hook or push is done this often as a ``grip``
# (`sim.contactors.interaction_poses`): the root held `STANDOFF_M` above the skin point while
# the digits close on the link; 0.4 gives 35 % of the default set's hand prints without a palm
# and the palm's share of a print 0.38 [IQR 0.00, 0.57] (real 0.42 [0.00, 0.56]).
PALM_CLEAR_P = 0.4
PALM_CLEAR_MODES = ("grasp", "hook", "flat")  # fingertip, palm-only and fist touches as they are
STANDOFF_M = (0.01, 0.02)  # m: the palm root's height over the skin point in a grip
MAX_PEN_FACTOR = 1.6  # max penetration = this x the tissue allowance (the depth saturates at it)
_PUSH = {
    "push_away": (1.0, 0.0),
    "pull": (-1.0, 0.0),
    "push_left": (0.0, 1.0),
    "push_right": (0.0, -1.0),
}  # hand-frame shear direction (x distal, y operator's left)


def hand_contactor(subject: Subject, rng: np.random.Generator | None = None) -> ContactorSpec:
    """The subject's hand as a contactor: palm centre at the root origin, palm facing -z.

    The hand's own root joints and actuators are removed (the runner adds its root); geom labels
    are 1..6 = index in `HAND_PARTS` + 1. ``rng`` is unused (the hand depends on the subject
    only, so the spec is cached per subject and its compiled scene by the runner).
    """
    return _hand_contactor(subject)


@lru_cache(maxsize=128)
def _hand_contactor(subject: Subject) -> ContactorSpec:
    cfg = subject.hand
    hand = build_hand_spec(cfg)
    for suffix in ROOT_JOINT_SUFFIXES:
        hand.delete(hand.actuator(cfg.prefix + suffix))
        hand.delete(hand.joint(cfg.prefix + suffix))
    labels = {HAND_PREFIX + g: HAND_PARTS.index(p) + 1 for g, p in geom_parts(hand).items()}
    spec = mujoco.MjSpec()
    spec.modelname = f"{subject.subject_id}_hand"
    root = spec.worldbody.add_body(name=ROOT)
    spec.attach(hand, frame=root.add_frame(pos=-palm_centre_m(subject)), prefix=HAND_PREFIX)
    desc = {
        "type": f"{cfg.side}_hand",
        "length_m": cfg.length_m,
        "breadth_m": cfg.breadth_m,
        "tissue_depth_m": cfg.tissue_depth_m,
        "subject": subject.subject_id,
        "sex": subject.sex,
    }
    if cfg.detail != "full":  # the default hand's description (and dataset bytes) stay as they were
        desc["detail"] = cfg.detail
    return ContactorSpec(
        spec,
        labels,
        "hand",
        f"{cfg.side}_hand",
        instance_id=-1,
        subject_id=int(subject.subject_id.lstrip("s") or -1),
        description=desc,
        max_penetration_m=MAX_PEN_FACTOR * cfg.tissue_depth_m * max(TISSUE_RATIO.values()),
    )


def palm_centre_m(subject: Subject) -> np.ndarray:
    """(3,) m: the palmar surface point under the middle metacarpal, in the hand frame
    (the hand's ``palm_center`` site)."""
    geo = hand_geometry(subject.hand.length_m, subject.hand.breadth_m)
    return np.array([0.3 * geo.length_m, 0.0, -geo.radii_m["middle"][0]])


def joint_name(subject: Subject, suffix: str) -> str:
    """Name of hand joint ``suffix`` (e.g. "index_pip") inside the contactor spec."""
    return f"{HAND_PREFIX}{subject.hand.prefix}{suffix}"


def _log_uniform(rng: np.random.Generator, lo_hi: tuple[float, float]) -> float:
    return float(np.exp(rng.uniform(np.log(lo_hi[0]), np.log(lo_hi[1]))))


def nominal_yaw_deg(action: str, position: str, side: str, rng: np.random.Generator) -> float:
    """Yaw of the hand (deg) by operator position (module docstring), before noise. In front
    and at the side the operator stands where the paper's people stood (`INDEX_END`): a right
    hand (``side``) and a left one yaw opposite ways so that the index finger is the one nearer
    the link's base; a free touch comes from anywhere."""
    hand = INDEX_END if side == "right" else -INDEX_END
    if position == "free":
        return float(rng.uniform(-180.0, 180.0))
    if action.startswith("grasp"):
        return GRASP_YAW_DEG * hand
    return 90.0 * hand if position == "front" else 180.0


def _shear_twist(action: str, force_n: float, yaw: float, rng: np.random.Generator):
    """(shear (along, around) N in the skin frame, twist N m) of ``action``."""
    twist = 0.0
    if action in ("grasp_twist_cw", "grasp_twist_ccw"):
        twist = (-1.0 if action.endswith("_cw") else 1.0) * rng.uniform(*TWIST_RANGE_NM)
    if action not in _PUSH:
        return (0.0, 0.0), twist
    hx, hy = _PUSH[action]
    mag = force_n * rng.uniform(*SHEAR_FRACTION)
    c, s = np.cos(yaw), np.sin(yaw)
    return (mag * (c * hx - s * hy), mag * (s * hx + c * hy)), twist


def finger_reach_count(part: Part, taxel: int, yaw_rad: float, length_m: float) -> int:
    """Taxels (count) within the hand's finger region when the palm centre is at ``taxel``: from
    the MCP row to the fingertips along the hand's x, half a breadth to either side (3D, m)."""
    rel = part.layout.positions_m - part.layout.positions_m[taxel]
    d = hand_direction(part, taxel, yaw_rad)
    along = rel @ d
    side = np.linalg.norm(rel - np.outer(along, d), axis=1)
    return int(
        np.count_nonzero(
            (along > 0.15 * length_m) & (along < 0.7 * length_m) & (side < 0.25 * length_m)
        )
    )


def toward_skin_yaw(
    part: Part, taxel: int, yaw_rad: float, length_m: float, rng: np.random.Generator
) -> float:
    """``yaw_rad`` or its opposite: with probability `TOWARD_SKIN_P` the one whose fingers reach
    more skin (an operator grasps where the skin is; the link is grasped from either side)."""
    flip = yaw_rad + np.pi
    flip_better = finger_reach_count(part, taxel, flip, length_m) > finger_reach_count(
        part, taxel, yaw_rad, length_m
    )
    keep_better = rng.random() < TOWARD_SKIN_P
    return float(flip if flip_better == keep_better else yaw_rad)


def wrap_shift_m(part: Part, taxel: int, yaw_rad: float, subject: Subject) -> float | None:
    """Shift (m) of the palm centre along the hand's x that puts the MCP row at the start of the
    edge the fingers cross (clipped to +-`MAX_GRASP_SHIFT_M`, so the contact stays near the aim);
    None when no edge lies within the fingers' reach (a face long enough for a flat hand)."""
    mcp = mcp_offset_m(subject)
    reach = mcp + 0.45 * subject.hand.length_m
    pos, normal = part.layout.positions_m[taxel], part.layout.normals[taxel]
    edge = edge_distance_m(part, pos, normal, hand_direction(part, taxel, yaw_rad), reach)
    if edge >= reach:
        return None
    most = MAX_GRASP_SHIFT_M if part.aim_band_mm is None else BAND_MAX_SHIFT_M
    return float(np.clip(edge - mcp, -most, most))


def plan_hand_interaction(
    action: str, operator_position: str, subject: Subject, part: Part, rng: np.random.Generator
) -> PressPlan:
    """A `PressPlan` for ``action`` (in `ACTIONS`) from ``operator_position`` by ``subject``.

    The aim is drawn by the shared policy (`sim.contactors.placement.draw_aim_taxel`); the palm
    centre goes there, shifted along the hand so that the MCP row lies on an edge the fingers cross
    (`wrap_shift_m`), or back for fingertips-only touches (`sim.contactors.interaction_poses`);
    a grip (`PALM_CLEAR_P`) holds the palm over the aim, `STANDOFF_M` off the skin.
    """
    if action not in ACTIONS or operator_position not in OPERATOR_POSITIONS:
        raise KeyError(
            f"unknown action/position {action!r}/{operator_position!r}; known: "
            f"{', '.join(ACTIONS)} / {', '.join(OPERATOR_POSITIONS)}"
        )
    k = draw_aim_taxel(part, rng)
    yaw_deg = (
        nominal_yaw_deg(action, operator_position, subject.handedness, rng) + subject.approach_deg
    )
    yaw = float(np.deg2rad(yaw_deg + rng.normal(0.0, YAW_SD_DEG)))
    if operator_position == "free":
        yaw = toward_skin_yaw(part, k, yaw, subject.hand.length_m, rng)
    mode, standoff = action_mode(action, rng), 0.0
    if mode in PALM_CLEAR_MODES and rng.random() < PALM_CLEAR_P:
        mode, standoff = "grip", float(rng.uniform(*STANDOFF_M))
    pose = finger_pose(mode, subject, rng, wrap_shift_m(part, k, yaw, subject))
    family = "free" if action == "free" else ("grasp" if action.startswith("grasp") else "push")
    force = _log_uniform(rng, FORCE_RANGE_N[family]) * subject.force_scale
    shear, twist = _shear_twist(action, force, yaw, rng)
    site = part.flat_mm[k] + hand_offset_uv(part, k, pose.shift_m, yaw)
    tilt = np.deg2rad(rng.normal(0.0, TILT_SD_DEG, 2)) + np.array([0.0, pose.pitch_rad])
    durations = tuple(d * rng.uniform(0.85, 1.15) for d in DURATIONS_S)
    return PressPlan(
        site_uv=(float(site[0]), float(site[1])),
        yaw_rad=yaw,
        tilt_rad=tuple(tilt.tolist()),
        force_n=float(force),
        shear_n=(float(shear[0]), float(shear[1])),
        twist_nm=float(twist),
        joint_targets={joint_name(subject, j): v for j, v in pose.targets_rad.items()},
        preshape=tuple(joint_name(subject, j) for j in pose.preshape),
        durations_s=durations,
        action=ACTIONS.index(action),
        operator_position=OPERATOR_POSITIONS.index(operator_position),
        standoff_m=standoff,
    )
