"""Human body parts that lean on, rest on or bump the robot: capsules and ellipsoids of human size.

Kinds (`BODY_KINDS`): forearm, upper arm, elbow, shoulder, chest, back, knee, head. Dimensions
are drawn per instance (`sim.contactors.objects.instance_rng`) uniformly over roughly the
5th-percentile woman to 95th-percentile man of ANSUR II (Gordon et al. 2014, US Army anthropometric
survey; values rounded, circumferences turned into radii by C / 2 pi):
- forearm circumference 24-32 cm -> belly half-width 38-50 mm, flattened 0.8; wrist 14-19 cm ->
  radius 22-30 mm; forearm (elbow-wrist) length 0.24-0.29 m;
- upper arm (biceps, relaxed) circumference 25-37 cm -> radius 40-58 mm; length 0.28-0.36 m;
- elbow: olecranon ~4-5 cm wide, protruding 10-15 mm behind the bone axes; flexion 60-120 deg;
- shoulder: deltoid cap 10-14 cm deep and wide (bideltoid breadth 41-52 cm minus chest);
- chest breadth 27-38 cm (broader than ANSUR II's 24-32 cm), chest depth 21-30 cm; back: the
  same trunk with the shoulder blades (scapulae ~10 x 15 cm, 1-2 cm proud of the ribs);
- knee: patella ~4.5-5.5 cm wide, femoral condyles 8.5-10.5 cm across, thigh circumference
  45-65 cm, calf 31-41 cm; flexion 60-110 deg;
- head breadth 14-16.5 cm, length 18-21 cm, height (chin to vertex) 21-24 cm.

Tissue (`sim.contactors.primitives.MATERIALS`, argued there): the rigid primitives stand for bone
plus the soft tissue that flattens on the link, so the compliance depth (solimp width) follows the
tissue's thickness with the hands' rule (`sim.contactors.hand`: palm 10.5 mm, fingertip 8.75 mm):
fat and muscle over bone (forearm, upper arm, chest, back, shoulder; 2-5 cm thick) 12-25 mm, skin
and pads over bone (elbow, knee, head; 5-10 mm) 6-12 mm. A forearm resting across the link, or a
chest leaning on it, thus lights a band several centimetres wide, as soft tissue does. Mass: gravity
is off in the press scene and the force is commanded, so mass only sets the contact dynamics;
MuJoCo's contact depth at a given force falls with the effective mass, so body parts get an
effective mass of 1-4 kg (the range of the arm segments, de Leva 1996: forearm 1.6 %, upper arm 2.7
% of 60-90 kg) instead of a trunk's.

Presses (`BODY_MODES`): leaning, resting an arm across, bumping, pressing. Forces (N) per kind:
resting a forearm or upper arm is its weight (forearm + hand 2.2 %, whole arm 5 % of 60-90 kg:
13-45 N) up to a lean of 60 N; leaning with the elbow or knee 10-60 / 10-80 N; with the shoulder,
chest or back part of the trunk's weight, 15-100 N (leaning on a table puts 10-20 % of body
weight, 60-180 N, on the forearms); the head rests with part of its weight (6.9 %, 40-60 N)
5-40 N. All stay below the ISO/TS 15066 quasi-static limits (chest 140 N, back and shoulders
210 N, arms 150-220 N, face 65 N).
"""

from __future__ import annotations

import numpy as np

from sim.contactors.press_modes import PressMode, draw_mode, plan_from_mode
from sim.contactors.primitives import (
    Prim,
    assemble,
    draw_compliance,
    instance_rng,
    pick,
    prim,
    rot,
    rotate,
    segment,
    unif,
    volume_m3,
)
from sim.contactors.spec import ContactorSpec, PressPlan
from tactile.errors import ConfigError

PREFIX = "bp_"
SOFT, THIN = "soft_tissue", "thin_tissue"
Built = tuple[list[Prim], dict, float]  # primitives, dimensions (m), effective mass (kg)


def _r(**kw: float) -> dict[str, float]:
    return {k: round(float(v), 5) for k, v in kw.items()}


def _forearm(rng: np.random.Generator) -> Built:
    """Lying along x: muscle belly (flattened ellipsoid) tapering into a wrist capsule, and the
    ulna's subcutaneous border (thin tissue) 2-4 mm proud of the belly, where a resting forearm
    bears (a ridge of peak pressure along the print)."""
    length, half_w, wrist = unif(rng, 0.24, 0.29), unif(rng, 0.038, 0.050), unif(rng, 0.022, 0.030)
    belly = prim("belly", "ellipsoid", (0.3 * length, half_w, 0.8 * half_w), material=SOFT)
    z = 0.8 * half_w - wrist  # wrist bottom flush with the belly's
    ridge, proud = unif(rng, 0.010, 0.014), unif(rng, 0.002, 0.004)
    zr = -0.8 * half_w + ridge - proud
    out = [
        belly,
        segment("wrist", "capsule", (0.1 * length, 0, z), (0.55 * length, 0, z), wrist, SOFT),
        segment("ulna", "capsule", (-0.2 * length, 0, zr), (0.5 * length, 0, zr), ridge, THIN),
    ]
    dims = _r(length=length, half_width=half_w, wrist_radius=wrist, ulna_proud=proud)
    return out, dims, unif(rng, 1.0, 1.6)


def _upper_arm(rng: np.random.Generator) -> Built:
    r, length = unif(rng, 0.040, 0.058), unif(rng, 0.28, 0.36)
    out = [segment("arm", "capsule", (-length / 2 + r, 0, 0), (length / 2 - r, 0, 0), r, SOFT)]
    return out, _r(radius=r, length=length), unif(rng, 1.6, 2.8)


def _flexed(
    rng: np.random.Generator,
    tip: Prim,
    radii: tuple[float, float],
    lengths,
    flexion_deg: tuple[float, float],
    above_m: float,
) -> tuple[list[Prim], float]:
    """A bony tip with two limb capsules rising at +-(flexion / 2) from its top, ``above_m``
    over the tip's centre (the elbow's and the knee's shape). Returns prims and flexion, rad."""
    flexion = np.deg2rad(unif(rng, *flexion_deg))
    joint = np.array([0.0, 0.0, above_m])
    out = [tip]
    for i, (s, r, length) in enumerate(zip((1, -1), radii, lengths, strict=True)):
        d = np.array([s * np.cos(flexion / 2), 0.0, np.sin(flexion / 2)])
        out.append(segment(f"limb{i}", "capsule", joint, joint + length * d, r, SOFT))
    return out, float(flexion)


def _elbow(rng: np.random.Generator) -> Built:
    """Leaning on the olecranon; forearm and upper arm rise from it (flexion 60-120 deg)."""
    semi = (unif(rng, 0.02, 0.025), unif(rng, 0.022, 0.028), unif(rng, 0.018, 0.022))
    radii = (unif(rng, 0.035, 0.045), unif(rng, 0.040, 0.055))  # forearm, upper arm
    proud = unif(rng, 0.010, 0.015)  # the olecranon stands proud of the limbs' surface
    tip = prim("olecranon", "ellipsoid", semi, material=THIN)
    out, flexion = _flexed(
        rng, tip, radii, (0.15, 0.18), (60.0, 120.0), -semi[2] + max(radii) + proud
    )
    return (
        out,
        _r(
            olecranon_half_width=semi[1],
            forearm_radius=radii[0],
            arm_radius=radii[1],
            proud=proud,
            flexion=flexion,
        ),
        unif(rng, 1.5, 2.5),
    )


def _shoulder(rng: np.random.Generator) -> Built:
    """Deltoid cap (ellipsoid) with the upper arm running on along x: a shoulder bump."""
    semi = (unif(rng, 0.055, 0.07), unif(rng, 0.05, 0.065), unif(rng, 0.045, 0.06))
    r = unif(rng, 0.040, 0.055)
    z = semi[2] - r + 0.01  # the arm sits 1 cm back from the deltoid's surface
    out = [
        prim("deltoid", "ellipsoid", semi, material=SOFT),
        segment("arm", "capsule", (0.03, 0, z), (0.25, 0, z), r, SOFT),
    ]
    return (
        out,
        _r(deltoid_x=semi[0], deltoid_y=semi[1], deltoid_z=semi[2], arm_radius=r),
        unif(rng, 2.5, 4.0),
    )


def _trunk(rng: np.random.Generator) -> tuple[Prim, tuple[float, float, float]]:
    """Trunk ellipsoid: half breadth along y, half height along x, half depth along z (m)."""
    semi = (unif(rng, 0.15, 0.22), unif(rng, 0.135, 0.19), unif(rng, 0.105, 0.15))
    return prim("trunk", "ellipsoid", semi, material=SOFT), semi


def _chest(rng: np.random.Generator) -> Built:
    """Leaning with the chest; with probability 0.5 two breast/pectoral ellipsoids stand out."""
    trunk, semi = _trunk(rng)
    out, bulge = [trunk], 0.0
    if rng.random() < 0.5:
        b = (unif(rng, 0.05, 0.07), unif(rng, 0.05, 0.07), unif(rng, 0.03, 0.05))
        bulge, y = b[2] * unif(rng, 0.3, 0.7), unif(rng, 0.08, 0.10)
        out += [
            prim(
                f"breast{i}", "ellipsoid", b, (-0.04, s * y, -semi[2] + b[2] - bulge), material=SOFT
            )
            for i, s in enumerate((-1, 1))
        ]
    return (
        out,
        _r(half_breadth=semi[1], half_height=semi[0], half_depth=semi[2], bulge=bulge),
        unif(rng, 3.0, 4.0),
    )


def _back(rng: np.random.Generator) -> Built:
    """Leaning back: the trunk with both shoulder blades 1-2 cm proud of the ribs."""
    trunk, semi = _trunk(rng)
    blade, proud, y = (0.07, 0.05, 0.02), unif(rng, 0.01, 0.02), unif(rng, 0.07, 0.10)
    z = -semi[2] + blade[2] - proud
    out = [trunk] + [
        prim(f"scapula{i}", "ellipsoid", blade, (0.05, s * y, z), material=SOFT)
        for i, s in enumerate((-1, 1))
    ]
    dims = _r(half_breadth=semi[1], half_depth=semi[2], scapula_proud=proud)
    return out, dims, unif(rng, 3.0, 4.0)


def _knee(rng: np.random.Generator) -> Built:
    """Pressing with the front of a flexed knee: patella on the condyles, thigh and shin rising."""
    pat = (unif(rng, 0.025, 0.03), unif(rng, 0.0225, 0.0275), unif(rng, 0.01, 0.013))
    cond = unif(rng, 0.0425, 0.0525)
    radii = (unif(rng, 0.07, 0.10), unif(rng, 0.05, 0.065))  # thigh, calf
    out, flexion = _flexed(
        rng,
        prim("patella", "ellipsoid", pat, material=THIN),
        radii,
        (0.2, 0.2),
        (60.0, 110.0),
        -pat[2] + max(radii) + 0.01,
    )
    condyles = prim(
        "condyles", "ellipsoid", (0.04, cond, 0.04), (0, 0, 0.045 - pat[2]), material=THIN
    )  # 5 mm behind the patella's surface
    out.insert(1, condyles)
    return (
        out,
        _r(
            patella_half_width=pat[1],
            condyle_half_width=cond,
            thigh_radius=radii[0],
            flexion=flexion,
        ),
        unif(rng, 3.0, 4.0),
    )


def _head(rng: np.random.Generator) -> Built:
    """Head ellipsoid resting on its side, back, forehead or crown."""
    semi = (unif(rng, 0.07, 0.0825), unif(rng, 0.09, 0.105), unif(rng, 0.105, 0.12))
    face = pick(rng, ("side", "back", "forehead", "crown"))
    pose = {
        "side": rot("y", np.pi / 2),
        "back": rot("x", np.pi / 2),
        "forehead": rot("x", -np.pi / 2),
        "crown": rot("x", np.pi),
    }[face]
    out = rotate([prim("skull", "ellipsoid", semi, material=THIN)], pose)
    return (
        out,
        _r(half_breadth=semi[0], half_length=semi[1], half_height=semi[2]) | {"face": face},
        unif(rng, 3.5, 4.5),
    )


BUILDERS = {
    "forearm": _forearm,
    "upper_arm": _upper_arm,
    "elbow": _elbow,
    "shoulder": _shoulder,
    "chest": _chest,
    "back": _back,
    "knee": _knee,
    "head": _head,
}
BODY_KINDS: tuple[str, ...] = tuple(BUILDERS)
_SKIN_RGBA = (0.88, 0.7, 0.6, 1.0)


def build_body_part(
    kind: str,
    rng: np.random.Generator | None,
    instance_id: int | None = None,
) -> ContactorSpec:
    """Body-part contactor ``kind`` (one of `BODY_KINDS`), instance ``instance_id``.

    The instance depends only on (kind, instance_id); ``rng`` draws the id when it is None
    (from 0..999). Geoms ``bp_<kind>_<part>``, labels 0, soft-tissue contact parameters.
    """
    if kind not in BUILDERS:
        raise ConfigError(f"unknown body part {kind!r}; known kinds: {', '.join(BUILDERS)}")
    if instance_id is None:
        instance_id = int(rng.integers(1000))
    irng = instance_rng(kind, instance_id)
    prims, dims, mass_kg = BUILDERS[kind](irng)
    fill = mass_kg / (1050.0 * sum(volume_m3(p) for p in prims))
    c = assemble(
        prims,
        "body",
        kind,
        instance_id,
        dims=dims,
        compliance=draw_compliance(irng, prims),
        fill=fill,
        prefix=PREFIX,
    )
    for g in c.spec.geoms:
        g.rgba = _SKIN_RGBA
    return c


# mode: (ranges; force scaled per kind), kinds that use it
_MODE_SHAPES = {
    "leaning": PressMode((0.0, 1.0), (0.0, 0.15), (0.0, 5.0), (0.3, 0.5, 0.6, 0.3)),
    "resting": PressMode((0.0, 0.5), (0.0, 0.08), (0.0, 0.0), (0.3, 0.4, 0.6, 0.3)),
    "bumped": PressMode((0.3, 1.0), (0.0, 0.25), (0.0, 5.0), (0.08, 0.08, 0.1, 0.1)),
    "pressed": PressMode((0.0, 1.0), (0.0, 0.15)),
}
BODY_MODES: dict[str, tuple[tuple[float, float], tuple[str, ...]]] = {  # force range N, modes
    "forearm": ((10.0, 60.0), ("resting", "leaning", "bumped")),
    "upper_arm": ((10.0, 60.0), ("resting", "leaning", "bumped")),
    "elbow": ((10.0, 60.0), ("leaning", "bumped", "pressed")),
    "shoulder": ((15.0, 100.0), ("bumped", "leaning")),
    "chest": ((15.0, 100.0), ("leaning", "bumped")),
    "back": ((15.0, 100.0), ("leaning", "resting")),
    "knee": ((10.0, 80.0), ("pressed", "bumped", "leaning")),
    "head": ((5.0, 40.0), ("resting", "leaning")),
}


def body_press(spec: ContactorSpec, rng: np.random.Generator) -> tuple[str, PressPlan]:
    """(mode, plan) for a body part: a mode of its kind, force within the kind's range
    (resting uses the lower half, a bump the upper 70 %)."""
    (lo, hi), modes = BODY_MODES[spec.name]
    mode = draw_mode(rng, {m: (1.0, _MODE_SHAPES[m]) for m in modes})
    shape = _MODE_SHAPES[mode]
    f0, f1 = (lo + shape.force_n[i] * (hi - lo) for i in (0, 1))
    scaled = PressMode((max(f0, lo), f1), shape.tilt_rad, shape.shear_n, shape.durations_s)
    return mode, plan_from_mode(rng, scaled)


def plan_body_press(spec: ContactorSpec, rng: np.random.Generator) -> PressPlan:
    """How body part ``spec`` is pressed (see `BODY_MODES`): forces N, angles rad, times s."""
    return body_press(spec, rng)[1]
