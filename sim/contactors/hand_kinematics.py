"""Hand geometry from anthropometry: segment lengths, radii and joint centres of a right hand.

Pure functions on floats and arrays; `sim.contactors.hand` turns the result into a MuJoCo model (and
mirrors it for a left hand).

Hand frame (right hand, home pose = flat open hand): origin at the centre of the distal wrist
crease, ``x`` distal (towards the middle fingertip), ``y`` radial (towards the thumb), ``z`` dorsal
(the palm faces ``-z``). All lengths in metres.

Sources
-------
- Segment lengths: Buchholz, Armstrong & Goldstein, "Anthropometric data for describing the
  kinematics of the human hand", Ergonomics 35(3), 1992 — joint-centre to joint-centre lengths
  as fractions of hand length (wrist crease to middle fingertip), `../shared/data/README.md`.
  The metacarpal rows are flagged there as less certain; they are used only for the length of the
  metacarpal capsules, while the carpometacarpal (CMC) line is placed so that the middle
  fingertip lands exactly at ``x = hand length`` (the definition of hand length). That puts the
  CMC line at 1 - 0.928 = 0.072 L from the crease (1.3 cm at L = 18 cm), plausible for the
  carpus; index/ring/little MCPs then fall 0, 4 and 8 % of L proximal of the middle MCP.
- Breadth: metacarpal hand breadth (radial edge of the index MCP to the ulnar edge of the little
  MCP). Default breadth 0.45 L: ANSUR-type means (about 8.9 cm / 19.3 cm for men and 7.8 cm /
  17.7 cm for women, ratio 0.44-0.46). MCP joint centres are spread over 0.74 of the breadth at
  a pitch of breadth/4 (four fingers side by side fill the breadth).
- Radii: capsule radius = half the finger breadth. Published finger breadths (ANSUR-type means,
  e.g. index proximal 2.0-2.2 cm, index distal 1.6-1.8 cm, thumb distal 2.0-2.3 cm for a hand
  breadth of 8-9 cm) are 0.22-0.24 (proximal) and 0.19-0.21 (distal) of hand breadth; the fingertip
  radius (about 8 mm) is what sets the contact-patch width (see `sim.contactors.hand`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

DIGITS: tuple[str, ...] = ("thumb", "index", "middle", "ring", "pinkie")
FINGERS: tuple[str, ...] = DIGITS[1:]

# Buchholz et al. 1992: (metacarpal, proximal, middle, distal) / hand length; thumb has no middle.
SEGMENT_FRACTIONS: dict[str, tuple[float, ...]] = {
    "thumb": (0.251, 0.196, 0.158),
    "index": (0.374, 0.265, 0.143, 0.097),
    "middle": (0.373, 0.277, 0.170, 0.108),
    "ring": (0.336, 0.259, 0.165, 0.107),
    "pinkie": (0.295, 0.206, 0.117, 0.093),
}
TYPICAL_BREADTH_RATIO = 0.45  # breadth / length, ANSUR-type means (see module docstring)

# Phalanx radius / breadth for (proximal, middle, distal); per-digit scale (thumb is stouter).
PHALANX_RADIUS_RATIO = np.array([0.112, 0.106, 0.102])
DIGIT_RADIUS_SCALE = {"thumb": 1.12, "index": 1.0, "middle": 1.02, "ring": 0.96, "pinkie": 0.86}
METACARPAL_RADIUS_RATIO = 0.13  # palm half-thickness ~1 cm at breadth 8 cm
THENAR_RADIUS_RATIO = 0.15  # thenar eminence around the first metacarpal
MCP_PITCH_RATIO = 0.25  # finger spacing at the MCPs / breadth
CMC_SPREAD = 0.55  # CMC lateral offsets / MCP lateral offsets (metacarpals fan out distally)
# Thumb CMC (trapezium): x / length, y and z / breadth. z = 0 puts the thenar capsule's lowest
# point 0.02 x breadth (1.6 mm) below the palmar plane and the thumb pads at rest in it: the real
# eminence is soft and flattens on a surface; lower (z = -0.08, measured) the thenar and the thumb
# protrude 6-8 mm and prop a palm pressed on a flat face up, so the palm pad never touches.
THUMB_CMC_XYZ = (0.06, 0.28, 0.0)
THUMB_HOME_ANGLE_DEG = 35.0  # first metacarpal in the palm plane, radially abducted from +x
THUMB_PRONATION_DEG = 90.0  # thumb pad faces ulnar (nail radial), 90 deg from the finger pads


@dataclass(frozen=True)
class HandGeometry:
    """Right-hand geometry in the hand frame (metres), home pose.

    lengths_m : digit -> (S,) float, segment lengths (metacarpal first; S = 3 thumb, 4 fingers)
    radii_m : digit -> (S,) float, capsule radius of each segment
    cmc_m : digit -> (3,) float, carpometacarpal joint centre
    mcp_m : digit -> (3,) float, metacarpophalangeal joint centre
    thumb_axis : (3,) float, unit direction of the first metacarpal (home pose)
    thumb_frame : (3, 3) float, columns = thumb phalanx frame (x along the thumb, y flexion axis)
    """

    length_m: float
    breadth_m: float
    lengths_m: dict[str, np.ndarray]
    radii_m: dict[str, np.ndarray]
    cmc_m: dict[str, np.ndarray]
    mcp_m: dict[str, np.ndarray]
    thumb_axis: np.ndarray
    thumb_frame: np.ndarray


def segment_lengths_m(length_m: float) -> dict[str, np.ndarray]:
    """Segment lengths (m) per digit = Buchholz fractions x hand length ``length_m`` (m)."""
    return {d: np.asarray(f) * length_m for d, f in SEGMENT_FRACTIONS.items()}


def segment_radii_m(breadth_m: float) -> dict[str, np.ndarray]:
    """Capsule radii (m) per digit, metacarpal first, scaled from hand breadth ``breadth_m`` (m)."""
    radii = {}
    for digit, scale in DIGIT_RADIUS_SCALE.items():
        phal = PHALANX_RADIUS_RATIO * scale * breadth_m
        if digit == "thumb":
            phal = phal[[0, 2]]
            meta = THENAR_RADIUS_RATIO * breadth_m
        else:
            meta = METACARPAL_RADIUS_RATIO * breadth_m
        radii[digit] = np.concatenate([[meta], phal])
    return radii


def finger_joint_centres_m(length_m: float, breadth_m: float) -> tuple[dict, dict]:
    """CMC and MCP centres (m) of the four fingers: two dicts finger -> (3,) float."""
    lengths = segment_lengths_m(length_m)
    pitch = MCP_PITCH_RATIO * breadth_m
    mcp_y = dict(zip(FINGERS, pitch * np.array([1.5, 0.5, -0.5, -1.5]), strict=True))
    drop = {f: _pad_drop_m(f, breadth_m) for f in FINGERS}
    run = {
        f: np.sqrt(lengths[f][0] ** 2 - ((1 - CMC_SPREAD) * mcp_y[f]) ** 2 - drop[f] ** 2)
        for f in FINGERS
    }
    cmc_x = length_m - lengths["middle"][1:].sum() - run["middle"]
    cmc = {f: np.array([cmc_x, CMC_SPREAD * mcp_y[f], 0.0]) for f in FINGERS}
    mcp = {f: np.array([cmc_x + run[f], mcp_y[f], -drop[f]]) for f in FINGERS}
    return cmc, mcp


def _pad_drop_m(finger: str, breadth_m: float) -> float:
    """Palmar offset (m) of a finger's MCP so that its proximal pad lies in the palmar plane of the
    metacarpals (a flat hand rests on palm *and* fingers; phalanges are thinner than the palm)."""
    proximal = PHALANX_RADIUS_RATIO[0] * DIGIT_RADIUS_SCALE[finger]
    return (METACARPAL_RADIUS_RATIO - proximal) * breadth_m


def thumb_frame(home_angle_deg: float, pronation_deg: float) -> np.ndarray:
    """(3, 3) rotation whose columns are the thumb phalanx axes (x along, y flexion, z dorsal).

    Positive rotation about the frame's y moves the thumb tip towards -z of the frame, i.e.
    towards the thumb pad, which faces palmar (-z) turned ``pronation_deg`` towards the ulnar side.
    """
    a = np.deg2rad(home_angle_deg)
    p = np.deg2rad(pronation_deg)
    x = np.array([np.cos(a), np.sin(a), 0.0])
    ulnar = np.array([np.sin(a), -np.cos(a), 0.0])
    pad = np.cos(p) * np.array([0.0, 0.0, -1.0]) + np.sin(p) * ulnar
    z = -pad
    return np.column_stack([x, np.cross(z, x), z])


def hand_geometry(length_m: float, breadth_m: float) -> HandGeometry:
    """Right-hand geometry (m) for a hand of length ``length_m`` and breadth ``breadth_m``."""
    lengths = segment_lengths_m(length_m)
    cmc, mcp = finger_joint_centres_m(length_m, breadth_m)
    frame = thumb_frame(THUMB_HOME_ANGLE_DEG, THUMB_PRONATION_DEG)
    x, y, z = THUMB_CMC_XYZ
    cmc["thumb"] = np.array([x * length_m, y * breadth_m, z * breadth_m])
    mcp["thumb"] = cmc["thumb"] + lengths["thumb"][0] * frame[:, 0]
    return HandGeometry(
        length_m=length_m,
        breadth_m=breadth_m,
        lengths_m=lengths,
        radii_m=segment_radii_m(breadth_m),
        cmc_m=cmc,
        mcp_m=mcp,
        thumb_axis=frame[:, 0],
        thumb_frame=frame,
    )


# Joint limits (degrees, right hand; sources in `sim.contactors.hand`) and torque limits (N m at
# strength 1: a light-to-moderate grip of 1-3 N per fingertip, below a palm press of 5-25 N, so
# closing fingers cannot lever the palm off a link — measured; maximal voluntary torques are 10 x
# higher).
JOINT_LIMITS_DEG: dict[str, tuple[float, float]] = {
    "mcp_abd": (-20.0, 20.0),
    "mcp_flex": (-30.0, 90.0),
    "pip": (0.0, 100.0),
    "dip": (-10.0, 80.0),
    # radial abduction (negative) to 35 deg beyond the home 35 deg: the thumb's axis up to 70 deg
    # from the middle finger's, the published maximal thumb-index angle (53.4 +- 6.5 deg) plus the
    # index's own abduction (17.2 +- 2.6 deg) (Chatzioglou et al., Anat Cell Biol 57(2), 2024);
    # was -15 (assumed), a thumb that could open only 38 deg from the index
    "thumb_cmc_flex": (-35.0, 50.0),
    "thumb_cmc_abd": (-10.0, 70.0),
    "thumb_mcp": (-10.0, 55.0),
    "thumb_ip": (-15.0, 80.0),
    "palm_arch": (0.0, 25.0),
}
MIDDLE_ABD_LIMIT_DEG = 15.0
JOINT_TORQUE_NM: dict[str, float] = {
    "mcp_abd": 0.1,
    "mcp_flex": 0.3,
    "pip": 0.15,
    "dip": 0.08,
    "thumb_cmc_flex": 0.4,
    "thumb_cmc_abd": 0.4,
    "thumb_mcp": 0.25,
    "thumb_ip": 0.12,
    "palm_arch": 0.3,
}
# Strength of each digit: a multiplier on the torque limits (and servo gains) of all its joints.
# Fitted so that the contact forces of 240 grasps of the default skin (tests/sim/
# test_hand_anchors.py) share as people's do: index 32.9, middle 34.8, ring 22.1, little 10.2 % of
# the four fingers' force (Li, J Hand Surg Am 27(5), 2002, maximal grip: 32.2 ± 3.8, 32.6 ± 4.3,
# 23.5 ± 4.5, 11.7 ± 4.9 %) and the thumb 17.0 % of the five digits' (J Hand Surg Am 2014, doi
# 10.1016/j.jhsa.2014.06.121: an estimated 17 % of grip strength). Equal limits gave 24.6, 19.1,
# 24.5, 31.8 % and a thumb of 2 %: a short little finger pushes hardest on the same torque. The
# fit depends on the grasp: the strengths fitted to grasps across the link (thumb 1.25, index 1.3,
# middle 1.66, ring 0.88, little 0.29) gave the middle finger 38.1 % and the little one 7.3 % once
# grasps held it obliquely (`sim.contactors.interactions.GRASP_YAW_DEG`).
DIGIT_STRENGTH: dict[str, float] = {
    "thumb": 1.35,
    "index": 1.2,
    "middle": 1.45,
    "ring": 0.95,
    "pinkie": 0.4,
}
SERVO_ERROR_AT_LIMIT_RAD = 0.6  # kp = torque limit / this: compliant, fingers conform to a surface


def mirror_pos(pos: np.ndarray, side: str) -> np.ndarray:
    """(3,) position of the right hand -> same point of the ``side`` hand (reflect y if left)."""
    return np.asarray(pos, float) * (np.array([1.0, -1.0, 1.0]) if side == "left" else 1.0)


def mirror_axis(axis: np.ndarray, side: str) -> np.ndarray:
    """(3,) hinge axis of the right hand -> axis giving the mirrored motion (axial vector)."""
    return np.asarray(axis, float) * (np.array([-1.0, 1.0, -1.0]) if side == "left" else 1.0)


def mirror_quat(quat: np.ndarray, side: str) -> np.ndarray:
    """(4,) body quaternion (w, x, y, z) of the right hand -> mirrored rotation."""
    return np.asarray(quat, float) * (np.array([1.0, -1.0, 1.0, -1.0]) if side == "left" else 1.0)


_FLEX_DEG = (("mcp_flex", 80.0), ("pip", 95.0), ("dip", 60.0))
_FINGERS_FLEXED = {f"{f}_{j}": v for f in FINGERS for j, v in _FLEX_DEG}
# Named hand poses: joint suffix (without the rh_/lh_ prefix) -> angle in degrees; others 0.
HAND_POSES_DEG: dict[str, dict[str, float]] = {
    "open": {},
    "fist": {
        **_FINGERS_FLEXED,
        "palm_arch": 15,
        "thumb_cmc_flex": 40,
        "thumb_cmc_abd": 30,
        "thumb_mcp": 40,
        "thumb_ip": 40,
    },
    "pinch": {  # thumb tip onto the index/middle tips (opposition, Kapandji)
        "index_mcp_flex": 50,
        "index_pip": 45,
        "index_dip": 20,
        "middle_mcp_flex": 50,
        "middle_pip": 45,
        "middle_dip": 20,
        "thumb_cmc_flex": 30,
        "thumb_cmc_abd": 40,
        "thumb_mcp": 5,
        "thumb_ip": 5,
    },
}
