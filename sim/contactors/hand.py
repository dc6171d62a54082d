"""A procedural articulated human hand built with `mujoco.MjSpec`, right or left.

Geometry comes from `sim.contactors.hand_kinematics` (Buchholz et al. 1992 segment ratios x hand
length, radii from hand breadth). The hand frame: origin at the wrist crease, ``x`` distal, ``z``
dorsal (palm faces ``-z``), thumb towards ``+y`` for a right hand and ``-y`` for a left one; the
left hand is the mirror image of the right through the ``xz`` plane.

Root. The palm body carries six joints (slides ``root_x/y/z`` then hinges ``root_rx/ry/rz``, in the
frame the hand is attached to), each driven by a position actuator with a force limit, and
gravity compensation on every hand body. Chosen over a mocap weld because (i) the pressing force
is bounded and readable (``actuator_force`` of the root slides) — a press is commanded as a
target beyond the surface and saturates at ``root_force_n``, which is what a subject's force
scale needs; (ii) the hand attaches with a prefix under any frame of a scene, with no equality
constraint to keep in step; (iii) compliance of the arm is the actuator's ``kp``.

Joints (degrees; positive = flexion, palmar abduction, spreading, cupping), active ranges after
the AAOS averages (Greene & Heckman, The Clinical Measurement of Joint Motion, 1994) and
Cobos et al., IROS 2008 (MCP abduction +-15-20): finger MCP flexion -30..90 (hyperextension
limited to 30), MCP abduction -20..20 (middle -15..15), PIP 0..100, DIP -10..80; thumb CMC
flexion across the palm -35..50 (radial abduction to the published maximal thumb-index angle,
`sim.contactors.hand_kinematics`), CMC palmar abduction -10..70, MCP -10..55, IP -15..80. Palm
arch (ring + little metacarpals about an axis between middle and ring metacarpals) 0..25: the
4th and 5th CMC joints flex about 10-15 and 20-30 degrees (Kapandji, The Physiology of the
Joints, vol. 1; El-Shennawy et al., J Hand Surg 2001).

Soft tissue. Every collision geom has ``solimp = (0, 0.99, w, 0.5, 2)``, ``solref = (0.01, 1)``
and ``priority = 1`` (so these parameters, not the other geom's, govern hand contacts): the
impedance rises from 0 at first touch to 0.99 at the allowance ``w``, so the force-depth law
stiffens like fingertip pulp (Serina et al., J Biomech 1997) and the depth stays below ``w``.
``w`` is per segment, `TISSUE_RATIO` x ``tissue_depth_m``: the rigid primitives stand for bone
plus soft tissue that flattens on a surface, and a deeper allowance lets them overlap the link as
far as the real tissue would spread. Anatomy (approximate, rounded): fingertip pulp 3-5 mm from
the distal phalanx to the skin; the palm's fat pad, palmar aponeurosis and intrinsic muscles put
roughly 8-15 mm of soft tissue under the metacarpals and more under the thenar/hypothenar
eminences; the phalanx pads carry a fibro-fatty pad a few millimetres thick over a finger 16-20
mm wide. The solver's depth is only a fraction of ``w`` at moderate forces, so ``w`` is tuned per
segment to what a contact must look like, and measured: the pulp's allowance (1.25 x) makes a
fingertip pressed with 2-5 N on MuJoCo's tactile plate sink 2.5-3 mm and touch 11-14 mm across
for hands of 15-22 cm (the chord of its capsule end; a pressed finger pad touches about 10-15 mm
across; tests/sim/test_hand.py); the phalanx pads (5 x) flatten across the finger's width,
each in the middle of its phalanx, clear of the flexion creases (`PAD_SPAN`), so a finger lying
on the link prints a row of pads; the palm takes 2.75 x. On the default set (`handskin stats`,
docs/stats.md) a hand contact lights a mean of 94 taxels and the palm holds 44 % of the labelled
hand pixels (the paper: almost 40 %); on the 10.6 mm skin a single 3.5 mm allowance on every
segment lit a median of 16 taxels, these allowances a mean of 39. The skin model reads pressure
from depth, so a part's share of a print's pressure follows its allowance more than its force
(docs/stats.md).

Strength. Each digit's torque limits are scaled by `DIGIT_STRENGTH` so that the fingers and thumb
share a grasp's contact force as people's do (`sim.contactors.hand_kinematics`).

Thenar. The thenar eminence (the thenar muscles' bellies over the first metacarpal, soft) is a
capsule of the palm along the first metacarpal's home axis; the metacarpal itself, with its skin,
is a thinner capsule (the proximal phalanx's radius) on the thumb's chain over its distal
`THUMB_METACARPAL_FREE` remainder. The eminence flattens on a surface while the thumb moves: as a
capsule rotating with the metacarpal it drove into the face under palmar abduction, so a palm
on the link held the thumb flat (abduction 4-20 deg of a 40-55 deg target, the thenar carrying
7-14 N, the thumb's tip 30-60 mm off a rounded edge; measured).

Labels. Collision geoms are named ``<prefix><part>_<segment>`` with part in `HAND_PARTS`
(the thenar eminence and the first metacarpal are "palm"); `geom_parts` / `geom_part_ids` recover
the tags from a spec or a compiled model, also after attaching under another prefix. Hand geoms
do not collide with each other (contype 2, conaffinity 1) but with any default geom.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import mujoco
import numpy as np

from sim.contactors.hand_kinematics import (
    DIGIT_STRENGTH,
    FINGERS,
    HAND_POSES_DEG,
    JOINT_LIMITS_DEG,
    JOINT_TORQUE_NM,
    MIDDLE_ABD_LIMIT_DEG,
    SERVO_ERROR_AT_LIMIT_RAD,
    TYPICAL_BREADTH_RATIO,
    HandGeometry,
    hand_geometry,
    mirror_axis,
    mirror_pos,
    mirror_quat,
)
from tactile.errors import ConfigError

HAND_PARTS: tuple[str, ...] = ("thumb", "index", "middle", "ring", "pinkie", "palm")  # ids 1..6
SIDES: tuple[str, ...] = ("right", "left")
# Collision detail of the palm. "full": per half, the heads of two metacarpals (capsules), a
# transverse heel capsule and a box between the metacarpals, recessed (the hollow of the palm);
# "coarse": the boxes alone, flush (a flat rectangular palm print, 6 fewer geoms). Fingers, thumb,
# thenar eminence, joints and actuators are the same in both.
HAND_DETAILS: tuple[str, ...] = ("full", "coarse")
HAND_LENGTH_RANGE_M = (0.15, 0.22)  # Albini & Cannata 2020: 90 volunteers, 15-22 cm
BREADTH_RATIO_RANGE = (0.38, 0.52)  # breadth / length
TISSUE_DEPTH_RANGE_M = (0.0015, 0.006)  # soft-tissue allowance (solimp width), metres
STRENGTH_RANGE = (0.25, 4.0)  # multiplier on the joint torque limits
TISSUE_SOLREF = (0.01, 1.0)  # (time constant s, damping ratio); >= 2 timesteps up to dt = 5 ms
SITE_GROUP = 5  # sites hidden in renderings by default
HAND_DENSITY = 1100.0  # kg/m^3, soft tissue and bone
PART_RGBA = {  # after the palette of Albini & Cannata 2020, Fig. 10
    "thumb": (0.90, 0.30, 0.25, 1.0),
    "index": (0.95, 0.70, 0.20, 1.0),
    "middle": (0.40, 0.75, 0.30, 1.0),
    "ring": (0.25, 0.55, 0.90, 1.0),
    "pinkie": (0.60, 0.35, 0.80, 1.0),
    "palm": (0.90, 0.75, 0.65, 1.0),
}
# Soft-tissue allowance (solimp width) per segment, as a multiple of the subject's softness scale
# `HandConfig.tissue_depth_m` (3.5 mm mean): palm 9.6 mm, phalanx pads 17.5 mm, fingertip pulp
# 4.4 mm at the mean (module docstring, "Soft tissue").
TISSUE_RATIO = {"palm": 2.75, "proximal": 5.0, "middle": 5.0, "distal": 1.25}
# The pad of a proximal or middle phalanx (and the thumb's proximal one): its capsule's segment
# spans these fractions of the phalanx, so with the capsule's round ends the pad touches about
# 0.2 x its length + its width (25-30 mm) and the flexion creases over the joints stay clear, as
# a finger pressed on glass prints one pad per phalanx. Measured against the real prints
# (../shared/data/real_hands, box-labelled parts; default forearm, 600 hand prints, seed 1): a
# finger's box 54 mm long (whole capsules, phalanges end to end) -> 46 mm (real: 44 [31, 62]),
# fingers with a mark of their own 0.25 -> 0.33 (real: 0.60 [0.40, 1.00]).
PAD_SPAN = np.array([0.4, 0.6])
# The hollow of the palm (full detail): a palm on a surface bears on the metacarpal heads (the
# distal palmar pad), the heel and the eminences, not over the metacarpal shafts. Each metacarpal
# capsule starts `METACARPAL_SHAFT` of the way from its base to its head, and the box between the
# metacarpals lies `PALM_HOLLOW_M` inside the heads' palmar surface. Measured against the real
# prints (600 hand prints of the default skin, seed 1; real fold 1 / 2): palms in two or more
# blobs 0.21 (whole capsules, flush box) -> 0.21 (box 4 or 8 mm in) -> 0.42 / 0.55 / 0.70 (and
# capsules from 0.5 / 0.7 / 0.8 of the shaft; real 0.66 / 0.67), the blobs' areas nearer the real
# ones (Kolmogorov-Smirnov 0.090 / 0.088 -> 0.066 / 0.076 at 0.7), the palm's share of a print's
# pixels 0.48 -> 0.40 (real 0.42; the paper: almost 40 %).
METACARPAL_SHAFT = 0.7
PALM_HOLLOW_M = 0.004
# The first metacarpal's own capsule starts this far along it (fraction of its length): its base
# lies inside the thenar eminence, by the carpus.
THUMB_METACARPAL_FREE = 0.35
_PART_RE = re.compile(r"(?:^|_)[rl]h_(thumb|index|middle|ring|pinkie|palm)_")


@dataclass(frozen=True)
class HandConfig:
    """One hand: size, side, tissue softness and strength (SI units)."""

    length_m: float = 0.18  # wrist crease to middle fingertip; mean of the 90 subjects
    breadth_m: float | None = None  # metacarpal breadth; None -> 0.45 x length (ANSUR-type mean)
    side: str = "right"  # "right" or "left"
    tissue_depth_m: float = 0.0035  # soft-tissue allowance: depth at which contacts are stiff
    strength: float = 1.0  # multiplier of the finger joint torque limits (1 = moderate grip)
    root_force_n: float = 40.0  # force limit of the root slide actuators (pressing force), N
    root_torque_nm: float = 4.0  # torque limit of the root hinge actuators, N m
    detail: str = "full"  # collision detail of the palm, one of `HAND_DETAILS`

    def __post_init__(self) -> None:
        if self.breadth_m is None:
            object.__setattr__(self, "breadth_m", TYPICAL_BREADTH_RATIO * self.length_m)
        _check("length_m", self.length_m, HAND_LENGTH_RANGE_M)
        lo, hi = BREADTH_RATIO_RANGE
        _check("breadth_m", self.breadth_m, (lo * self.length_m, hi * self.length_m))
        _check("tissue_depth_m", self.tissue_depth_m, TISSUE_DEPTH_RANGE_M)
        _check("strength", self.strength, STRENGTH_RANGE)
        _check("root_force_n", self.root_force_n, (0.1, 500.0))
        _check("root_torque_nm", self.root_torque_nm, (0.01, 50.0))
        if self.side not in SIDES:
            raise ConfigError(f"HandConfig.side={self.side!r} unknown; choose one of {SIDES}")
        if self.detail not in HAND_DETAILS:
            raise ConfigError(
                f"HandConfig.detail={self.detail!r} unknown; choose one of {HAND_DETAILS}"
            )

    @property
    def prefix(self) -> str:
        """Name prefix of every element: ``rh_`` or ``lh_``."""
        return "rh_" if self.side == "right" else "lh_"


def _check(field: str, value: float, bounds: tuple[float, float]) -> None:
    lo, hi = bounds
    if not np.isfinite(value) or not lo - 1e-12 <= value <= hi + 1e-12:
        raise ConfigError(f"HandConfig.{field}={value!r} out of range; allowed [{lo:g}, {hi:g}]")


def geom_parts(spec: mujoco.MjSpec) -> dict[str, str]:
    """Collision geom name -> hand part (one of `HAND_PARTS`) for every hand geom of ``spec``."""
    return {g.name: m.group(1) for g in spec.geoms if g.contype and (m := _PART_RE.search(g.name))}


def geom_part_ids(model: mujoco.MjModel) -> np.ndarray:
    """(ngeom,) int64: 1..6 = index in `HAND_PARTS` + 1 for hand collision geoms, 0 otherwise."""
    ids = np.zeros(model.ngeom, dtype=np.int64)
    for i in range(model.ngeom):
        match = _PART_RE.search(model.geom(i).name)
        if match and model.geom_contype[i]:
            ids[i] = HAND_PARTS.index(match.group(1)) + 1
    return ids


def build_hand_spec(cfg: HandConfig) -> mujoco.MjSpec:
    """A standalone spec of the hand; attach it under a scene frame with a subject prefix.

    Names already start with ``rh_``/``lh_``; attach with e.g. ``prefix="s0007_"`` (an empty
    prefix works but MuJoCo then logs a warning to MUJOCO_LOG.TXT in the working directory).

    Bodies ``<p>palm`` (root, 6 joints) > ``<p>palm_ulnar`` (arch) and the digit chains
    ``<p><digit>_proximal|middle|distal`` (thumb: ``metacarpal|proximal|distal``); sites
    ``<p><digit>_tip`` (fingertip) and ``<p>palm_center`` (palmar surface); one position
    actuator per joint, named after it, with a force limit.
    """
    spec = mujoco.MjSpec()
    spec.modelname = f"{cfg.prefix}hand"
    spec.compiler.degree = False
    _Builder(spec, cfg, hand_geometry(cfg.length_m, cfg.breadth_m)).build()
    return spec


def set_hand_options(spec: mujoco.MjSpec, timestep_s: float = 0.002) -> None:
    """Simulation options the hand is tuned for (set them on the *scene* spec).

    implicitfast integration (position servos with damping), elliptic friction cones, and a
    time step of at most half the tissue time constant ``TISSUE_SOLREF[0]`` (refsafe).
    """
    top = TISSUE_SOLREF[0] / 2
    if not 0 < timestep_s <= top:
        raise ConfigError(f"timestep_s={timestep_s!r} out of range; allowed (0, {top:g}]")
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.timestep = timestep_s


def apply_pose(model: mujoco.MjModel, data: mujoco.MjData, pose: str, prefix: str) -> None:
    """Set qpos and position targets of the ``prefix`` hand's finger joints to a named pose.

    pose : key of `HAND_POSES_DEG` ("open", "fist", "pinch"); unlisted finger joints go to 0,
    root joints are left alone. Calls `mujoco.mj_kinematics`.
    """
    if pose not in HAND_POSES_DEG:
        raise ConfigError(f"unknown hand pose {pose!r}; known poses: {', '.join(HAND_POSES_DEG)}")
    angles = HAND_POSES_DEG[pose]
    for j in range(model.njnt):
        name = model.joint(j).name
        suffix = name.split(prefix, 1)[1] if prefix in name else None
        if suffix is None or suffix.startswith("root_"):
            continue
        value = np.deg2rad(angles.get(suffix, 0.0))
        data.qpos[model.jnt_qposadr[j]] = value
        actuator = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, name)
        if actuator >= 0:
            data.ctrl[actuator] = value
    mujoco.mj_kinematics(model, data)


class _Builder:
    """Adds the hand's bodies, geoms, joints, sites and actuators to ``spec`` (right, mirrored)."""

    def __init__(self, spec: mujoco.MjSpec, cfg: HandConfig, geo: HandGeometry) -> None:
        self.spec, self.cfg, self.geo, self.p = spec, cfg, geo, cfg.prefix
        self.visual = spec.add_default(f"{self.p}visual", spec.default)
        self.collision = spec.add_default(f"{self.p}collision", spec.default)
        _set_visual(self.visual.geom)
        _set_collision(self.collision.geom, cfg.tissue_depth_m)

    def build(self) -> None:
        palm = self._root()
        self._palm_geoms(palm, ("index", "middle"), heel=(0.32, -0.02))
        ulnar = self._body(palm, "palm_ulnar", np.zeros(3))
        self._hinge(ulnar, "palm_arch", (1.0, 0.0, 0.0), JOINT_LIMITS_DEG["palm_arch"])
        self._palm_geoms(ulnar, ("pinkie", "ring"), heel=(-0.02, -0.36))
        for finger in FINGERS:
            self._finger(palm if finger in ("index", "middle") else ulnar, finger)
        self._thumb(palm)
        self._actuators()

    def _root(self) -> mujoco.MjsBody:
        palm = self._body(self.spec.worldbody, "palm", np.zeros(3))
        for i, name in enumerate("xyz"):
            axis = np.eye(3)[i]
            palm.add_joint(name=f"{self.p}root_{name}", type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis)
        for i, name in enumerate(("rx", "ry", "rz")):
            palm.add_joint(name=f"{self.p}root_{name}", axis=np.eye(3)[i], armature=1e-3)
        r = self.geo.radii_m["middle"][0]
        pos = [0.3 * self.geo.length_m, 0, -r]
        palm.add_site(name=f"{self.p}palm_center", pos=pos, group=SITE_GROUP)
        return palm

    def _body(self, parent, name: str, pos, quat=(1.0, 0, 0, 0)) -> mujoco.MjsBody:
        side = self.cfg.side
        return parent.add_body(
            name=f"{self.p}{name}",
            pos=mirror_pos(pos, side),
            quat=mirror_quat(quat, side),
            gravcomp=1.0,
        )

    def _hinge(self, body, name: str, axis, limits_deg, armature: float = 2e-4) -> None:
        body.add_joint(
            name=f"{self.p}{name}",
            axis=mirror_axis(axis, self.cfg.side),
            armature=armature,
            range=np.deg2rad(limits_deg),
            limited=mujoco.mjtLimited.mjLIMITED_TRUE,
        )

    def _capsule(self, body, part: str, segment: str, start, end, radius: float) -> None:
        """Collision capsule ``<p><part>_<segment>`` plus its visual twin (coloured by part)."""
        fromto = np.concatenate([mirror_pos(start, self.cfg.side), mirror_pos(end, self.cfg.side)])
        name = f"{self.p}{part}_{segment}"
        kind = mujoco.mjtGeom.mjGEOM_CAPSULE
        geom = body.add_geom(
            self.collision, name=name, type=kind, fromto=fromto, size=[radius, 0, 0]
        )
        self._tissue(geom, "palm" if part == "palm" else segment)
        body.add_geom(
            self.visual,
            name=f"{name}_visual",
            type=kind,
            fromto=fromto,
            size=[radius, 0, 0],
            rgba=PART_RGBA[part],
        )

    def _tissue(self, geom: mujoco.MjsGeom, segment: str) -> None:
        """Set the geom's tissue allowance: `TISSUE_RATIO` of the segment x the fingertip's."""
        width = TISSUE_RATIO.get(segment, 1.0) * self.cfg.tissue_depth_m
        geom.solimp = [0.0, 0.99, width, 0.5, 2.0]

    def _palm_geoms(self, body, fingers: tuple[str, str], heel: tuple[float, float]) -> None:
        """Metacarpal capsules of two fingers and a transverse heel capsule (y / breadth) at
        full detail; the flat box between the metacarpals at every detail."""
        geo = self.geo
        if self.cfg.detail == "coarse":
            self._palm_box(
                body,
                "radial" if heel[0] > 0 else "ulnar",
                [geo.cmc_m[f] for f in fingers],
                [geo.mcp_m[f] for f in fingers],
            )
            return
        for f in fingers:
            r = geo.radii_m[f][0]
            head = geo.cmc_m[f] + METACARPAL_SHAFT * (geo.mcp_m[f] - geo.cmc_m[f])
            self._capsule(body, "palm", f"{f}_metacarpal", head, geo.mcp_m[f], r)
        x, r = 0.045 * geo.length_m, geo.radii_m["middle"][0]
        ends = [np.array([x, y * geo.breadth_m, 0.0]) for y in heel]
        half = "radial" if heel[0] > 0 else "ulnar"
        self._capsule(body, "palm", f"{half}_heel", *ends, r)
        cmc, mcp = [geo.cmc_m[f] for f in fingers], [geo.mcp_m[f] for f in fingers]
        self._palm_box(body, half, cmc, mcp, PALM_HOLLOW_M)

    def _palm_box(self, body, half: str, cmc: list, mcp: list, hollow_m: float = 0.0) -> None:
        """Box filling the palmar side between two metacarpals, ``hollow_m`` (m) inside the
        palmar surface of the metacarpal heads (0: a flat palm, no grooves)."""
        r = self.geo.radii_m["middle"][0]
        x0, x1 = cmc[0][0], min(m[0] for m in mcp)
        y_out = 0.5 * (cmc[0][1] + mcp[0][1])  # outer metacarpal; the inner edge is the arch axis
        pos = mirror_pos(((x0 + x1) / 2, y_out / 2, -r / 2 + hollow_m), self.cfg.side)
        size = [(x1 - x0) / 2, abs(y_out) / 2, r / 2]
        kind, name = mujoco.mjtGeom.mjGEOM_BOX, f"{self.p}palm_{half}_pad"
        pad = body.add_geom(self.collision, name=name, type=kind, pos=pos, size=size)
        self._tissue(pad, "palm")
        body.add_geom(
            self.visual,
            name=f"{name}_visual",
            type=kind,
            pos=pos,
            size=size,
            rgba=PART_RGBA["palm"],
        )

    def _finger(self, parent, finger: str) -> None:
        spread = -1.0 if finger in ("ring", "pinkie") else 1.0
        abd = JOINT_LIMITS_DEG["mcp_abd"]
        if finger == "middle":
            abd = (-MIDDLE_ABD_LIMIT_DEG, MIDDLE_ABD_LIMIT_DEG)
        body = self._body(parent, f"{finger}_proximal", self.geo.mcp_m[finger])
        self._hinge(body, f"{finger}_mcp_abd", (0, 0, spread), abd)
        self._hinge(body, f"{finger}_mcp_flex", (0, 1, 0), JOINT_LIMITS_DEG["mcp_flex"])
        names = ("proximal", "middle", "distal")
        self._phalanges(body, finger, names, (("pip", "pip"), ("dip", "dip")))

    def _phalanges(self, body, digit: str, names, joints) -> None:
        """Phalanx capsules ``names`` (the first in ``body``); ``joints``: (name, limit key)."""
        lengths, radii = self.geo.lengths_m[digit][1:], self.geo.radii_m[digit][1:]
        for k, (seg, length, r) in enumerate(zip(names, lengths, radii, strict=True)):
            if k > 0:
                body = self._body(body, f"{digit}_{seg}", (lengths[k - 1], 0, 0))
                name, key = joints[k - 1]
                self._hinge(body, f"{digit}_{name}", (0, 1, 0), JOINT_LIMITS_DEG[key])
            start, end = (0.0, length - r) if seg == "distal" else PAD_SPAN * length
            self._capsule(body, digit, seg, (start, 0, 0), (end, 0, 0), r)
        tip = mirror_pos((lengths[-1], 0, 0), self.cfg.side)
        body.add_site(name=f"{self.p}{digit}_tip", pos=tip, group=SITE_GROUP)

    def _thumb(self, palm) -> None:
        """Thenar eminence on the palm, then the thumb's chain from the CMC (module docstring)."""
        geo = self.geo
        a, cmc = geo.thumb_axis, geo.cmc_m["thumb"]
        lengths, radii = geo.lengths_m["thumb"], geo.radii_m["thumb"]
        self._capsule(palm, "palm", "thenar", cmc, cmc + lengths[0] * a, radii[0])
        meta = self._body(palm, "thumb_metacarpal", cmc)
        self._hinge(meta, "thumb_cmc_flex", (0, 0, -1), JOINT_LIMITS_DEG["thumb_cmc_flex"])
        self._hinge(meta, "thumb_cmc_abd", (-a[1], a[0], 0), JOINT_LIMITS_DEG["thumb_cmc_abd"])
        start = THUMB_METACARPAL_FREE * lengths[0] * a
        self._capsule(meta, "palm", "thumb_metacarpal", start, lengths[0] * a, radii[1])
        quat = np.zeros(4)
        mujoco.mju_mat2Quat(quat, geo.thumb_frame.flatten())
        body = self._body(meta, "thumb_proximal", lengths[0] * a, quat)
        self._hinge(body, "thumb_mcp", (0, 1, 0), JOINT_LIMITS_DEG["thumb_mcp"])
        self._phalanges(body, "thumb", ("proximal", "distal"), (("ip", "thumb_ip"),))

    def _actuators(self) -> None:
        for joint in self.spec.joints:
            self._actuator(joint)

    def _actuator(self, joint: mujoco.MjsJoint) -> None:
        suffix = joint.name[len(self.p) :]
        if suffix.startswith("root_"):
            slide = joint.type == mujoco.mjtJoint.mjJNT_SLIDE
            limit = self.cfg.root_force_n if slide else self.cfg.root_torque_nm
            kp = limit / (0.02 if slide else 0.2)  # saturates 2 cm / 0.2 rad short of target
            ctrl = (-1.0, 1.0) if slide else (-np.pi, np.pi)
        else:
            key = suffix if suffix in JOINT_TORQUE_NM else suffix.split("_", 1)[1]
            digit = DIGIT_STRENGTH.get(suffix.split("_", 1)[0], 1.0)
            limit = JOINT_TORQUE_NM[key] * self.cfg.strength * digit
            kp, ctrl = limit / SERVO_ERROR_AT_LIMIT_RAD, tuple(joint.range)
        act = self.spec.add_actuator(
            name=joint.name,
            target=joint.name,
            trntype=mujoco.mjtTrn.mjTRN_JOINT,
            forcelimited=mujoco.mjtLimited.mjLIMITED_TRUE,
            forcerange=[-limit, limit],
            ctrllimited=mujoco.mjtLimited.mjLIMITED_TRUE,
            ctrlrange=ctrl,
        )
        act.set_to_position(kp=kp, dampratio=1.0)


def _set_visual(geom: mujoco.MjsGeom) -> None:
    geom.group, geom.contype, geom.conaffinity, geom.density = 2, 0, 0, 0.0


def _set_collision(geom: mujoco.MjsGeom, tissue_depth_m: float) -> None:
    """Group 3; collides with the world (conaffinity 1) but not with its own hand (contype 2)."""
    geom.group, geom.contype, geom.conaffinity, geom.priority = 3, 2, 1, 1
    geom.density, geom.condim, geom.friction = HAND_DENSITY, 3, [0.8, 0.005, 0.0001]
    geom.solref = TISSUE_SOLREF
    geom.solimp = [0.0, 0.99, tissue_depth_m, 0.5, 2.0]
    geom.rgba = PART_RGBA["palm"]
