"""Hand poses of the interactions (joint targets with the subject's noise) and site offsets.

Targets are degrees of flexion (positive = flexion, palmar abduction, cupping; `sim.hand`). For
grasps they lie beyond the link: the torque-limited finger servos stop where the fingers meet it.
Free touches pick one of four variants (Albini & Cannata 2020, Fig. 6: whole hands, fingertips
only, different pressures): flat hand, fingertips only (a random subset of digits flexed so the
tips point at the skin and hold the palm off it), palm only (fingers lifted), loosely curled.
"""

from __future__ import annotations

import numpy as np

from sim.hand_kinematics import FINGERS, JOINT_LIMITS_DEG, hand_geometry
from sim import placement
from sim.parts import Part
from sim.subjects import Subject

# The forearm is ~15 cm across: a grasp puts the palm on one face and the fingers round an
# edge; targets a little beyond the edge (large errors saturate the servos, and four saturated
# fingers pushing on the rounded edge lift the palm off the face: measured).
_GRASP = {"mcp_flex": 55.0, "pip": 30.0, "dip": 15.0}
# The thumb lies on the surface beside the palm (a large link cannot be opposed across); at 0 the
# thumb capsules protrude ~6 mm below the palmar plane and prop the palm up, so it is lifted.
_GRASP_THUMB = {"thumb_cmc_abd": 5.0, "thumb_cmc_flex": -10.0, "thumb_mcp": 10.0, "thumb_ip": 10.0}
_FLAT = {"mcp_flex": 10.0, "pip": 10.0, "dip": 5.0}  # conforms round the edge (torque-limited)
_FLAT_THUMB = {"thumb_cmc_abd": -10.0, "thumb_cmc_flex": -15.0, "thumb_mcp": 0.0, "thumb_ip": 0.0}
_HOOK = {"mcp_flex": 40.0, "pip": 45.0, "dip": 20.0}
_TIPS = {"mcp_flex": 55.0, "pip": 40.0, "dip": 10.0}  # tips point at the skin
_LIFTED = {"mcp_flex": -25.0, "pip": 0.0, "dip": 0.0}
_CURLED = {"mcp_flex": 45.0, "pip": 60.0, "dip": 30.0}
FREE_VARIANTS = ("flat", "fingertips", "palm", "curled")
FREE_PROBS = (0.3, 0.5, 0.05, 0.15)  # fingertip touches are common in Fig. 6


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


def _free_pose(subject: Subject, rng: np.random.Generator) -> tuple[dict[str, float], float]:
    """Pose (deg) and fingertip offset (m, hand x from the palm centre; 0 = palm-centred)."""
    variant = FREE_VARIANTS[int(rng.choice(len(FREE_VARIANTS), p=FREE_PROBS))]
    if variant == "flat":
        return {**_fingers(_FLAT), **_FLAT_THUMB}, 0.0
    if variant == "palm":
        return {**_fingers(_LIFTED), **_FLAT_THUMB}, 0.0
    if variant == "curled":
        return {**_fingers(_CURLED), **_GRASP_THUMB, "palm_arch": 5.0}, 0.0
    n = int(rng.integers(1, 5))
    down = [str(f) for f in rng.choice(FINGERS, size=n, replace=False)]
    up = [f for f in FINGERS if f not in down]
    pose = {**_fingers(_TIPS, down), **_fingers(_LIFTED, up), **_FLAT_THUMB}
    return pose, fingertip_reach_m(subject, down)


def fingertip_reach_m(subject: Subject, fingers: list[str]) -> float:
    """Mean distance (m) along hand x from the palm centre to the tips of ``fingers`` in the
    fingertips pose (proximal phalanx at `_TIPS` mcp flexion, the rest pointing down)."""
    geo = hand_geometry(subject.hand.length_m, subject.hand.breadth_m)
    mcp = np.deg2rad(_TIPS["mcp_flex"])
    reach = [geo.mcp_m[f][0] + geo.lengths_m[f][1] * np.cos(mcp) for f in fingers]
    return float(np.mean(reach) - 0.3 * geo.length_m)


def finger_pose(
    action: str, subject: Subject, rng: np.random.Generator
) -> tuple[dict[str, float], float]:
    """(joint suffix -> target rad, fingertip offset m) of ``action`` with the subject's noise."""
    if action.startswith("grasp"):
        pose, reach = {**_fingers(_GRASP), **_GRASP_THUMB, "palm_arch": 5.0}, 0.0
    elif action == "pull":
        pose, reach = {**_fingers(_HOOK), **_FLAT_THUMB, "palm_arch": 3.0}, 0.0
    elif action == "free":
        pose, reach = _free_pose(subject, rng)
    else:
        pose, reach = {**_fingers(_FLAT), **_FLAT_THUMB}, 0.0
    return _noisy(pose, subject.pose_noise_deg, rng), reach


def hand_direction(part: Part, taxel: int, yaw_rad: float) -> np.ndarray:
    """(3,) unit tangent at ``taxel``: the hand's x (distal) yawed by ``yaw_rad`` from the link
    axis about the outward normal (the runner's skin frame, `sim.episode.site_pose`)."""
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
