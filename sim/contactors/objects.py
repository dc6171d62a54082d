"""Object contactors (non-hand): primitives and composites of varied size, edges and stiffness.

Every object is a `ContactorSpec` made only of MuJoCo primitives (so `sim.skin.readout` attributes
each taxel exactly); its lowest point is the root origin and its ``+z`` points away from the skin.
An *instance* = (type, sizes, presentation, stiffness) is drawn from a per-instance seed
``SeedSequence((crc32(kind), instance_id))``, so the same (kind, instance_id) always gives the
same object and a dataset can keep train and test instances disjoint.

Stiffness. MuJoCo's penetration depth stands for the joint deformation of skin and object, so
the contact law is the hand's (`sim.contactors.hand`: ``solimp = (0, 0.99, w, 0.5, 2)``, ``solref =
(0.01, 1)``, priority 1) with the *compliance depth* ``w`` set by the material: rigid bodies (steel,
aluminium, ceramic) only compress the skin's 2 mm silicone dielectric (`sim.skin.model.SkinConfig`:
~1 mm at the 100 kPa full scale) -> 1.0-1.5 mm; wood and hard plastic add a little -> 1.5-3 mm;
rubber (Shore A 40-70, a few mm of give on balls, grips) -> 3-6 mm; soft foam and sponges
(E ~ 10-100 kPa, centimetres thick) -> 6-12 mm; cushions, stuffed bundles and soft inflated
balls (`sim.contactors.primitives.MATERIALS`: padding, inflatable) -> 15-30 mm. Hands' tissue
allowances are 3.75-18 mm (`sim.contactors.hand.TISSUE_RATIO`), so stiffness overlaps.

Broad objects (`sim.contactors.nonhand.BROAD_OBJECTS`): cushions, bundles and big balls, with plates
and boxes pressed flat, light a print as large as a hand's (tens of cm^2).

Hard negatives (`HARD_NEGATIVES`): rakes, combs and rod bundles have 2-6 parallel elongated
geoms of finger-like radius 6-11 mm (the hand's phalanx radii: 0.10-0.11 x breadth 6-10 cm) at
finger-like centre spacing 15-25 mm (MCP pitch = breadth / 4), so blob count, size and spacing
alone cannot tell them from fingers.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sim.contactors.press_modes import PressMode, draw_mode, plan_from_mode
from sim.contactors.primitives import (
    FINGER_RADIUS_M,
    FINGER_SPACING_M,
    Prim,
    _dims,
    assemble,
    draw_compliance,
    instance_rng,
    pick,
    prim,
    rot,
    rotate,
    segment,
    unif,
)
from sim.contactors.spec import ContactorSpec, PressPlan
from tactile.errors import ConfigError

# --- builders: rng -> (primitives, dimensions in m, fill fraction) --------------------------
# Sizes: everyday objects (balls from a table-tennis ball, r 20 mm (ITTF: 40 mm across), to a
# football, r 110 mm (IFAB Law 2: 68-70 cm round); mugs 70-96 mm across; tools after common
# hand-tool dimensions); each range is in the builder.

Built = tuple[list[Prim], dict, float]
_HARD, _SOFT = ("steel", "aluminium", "wood", "hard_plastic"), ("rubber", "foam")


def _ball(rng: np.random.Generator) -> Built:
    r = unif(rng, 0.02, 0.11, log=True)  # table-tennis ball .. football
    mat = pick(rng, ("rubber", "foam", "hard_plastic") + (("steel", "wood") if r < 0.04 else ()))
    fill = 1.0 if mat in ("steel", "wood", "foam") else 0.15  # hollow balls
    return [prim("ball", "sphere", (r,), material=mat)], _dims(radius=r), fill


def _box(rng: np.random.Generator) -> Built:
    half = np.array([unif(rng, 0.02, 0.15), unif(rng, 0.02, 0.10), unif(rng, 0.01, 0.08)])
    mat = pick(rng, ("wood", "hard_plastic", "foam", "steel", "rubber"))
    face = bool(rng.random() < 0.6)  # a face, or an edge (tilted 30-60 deg about x)
    mat3 = np.eye(3) if face else rot("x", unif(rng, np.pi / 6, np.pi / 3))
    b = [prim("box", "box", half, mat=mat3, material=mat)]
    fill = {"steel": 0.1, "wood": 0.5, "hard_plastic": 0.3}.get(mat, 1.0)  # cases and crates
    return b, _dims(half_x=half[0], half_y=half[1], half_z=half[2], edge=float(not face)), fill


def _cylinder_side(rng: np.random.Generator) -> Built:
    r, h = unif(rng, 0.01, 0.05, log=True), unif(rng, 0.04, 0.15)  # pen/pipe .. bottle/can/roll
    mat = pick(rng, (*_HARD, "rubber"))
    c = [prim("cylinder", "cylinder", (r, h), mat=rot("y", np.pi / 2), material=mat)]
    return c, _dims(radius=r, half_length=h), 1.0 if mat != "aluminium" else 0.2


def _cylinder_end(rng: np.random.Generator) -> Built:
    r, h = unif(rng, 0.008, 0.045, log=True), unif(rng, 0.02, 0.08)  # marker end .. jar lid
    mat = pick(rng, _HARD + _SOFT)
    return [prim("cylinder", "cylinder", (r, h), material=mat)], _dims(radius=r, half_length=h), 1.0


def _plate(rng: np.random.Generator) -> Built:
    # tray, book, cutting board
    half = (unif(rng, 0.08, 0.2), unif(rng, 0.06, 0.15), unif(rng, 0.002, 0.012))
    mat = pick(rng, ("wood", "hard_plastic", "aluminium", "foam"))
    dims = _dims(half_x=half[0], half_y=half[1], half_z=half[2])
    return [prim("plate", "box", half, material=mat)], dims, 1.0


def _plate_edge(rng: np.random.Generator) -> Built:
    """A plate standing on an edge of thickness 2-12 mm, sharp or rounded (radius = t / 2)."""
    t, half_l, half_h = unif(rng, 0.002, 0.012), unif(rng, 0.05, 0.15), unif(rng, 0.03, 0.10)
    mat, rounded = pick(rng, _HARD), bool(rng.random() < 0.5)
    z0 = t / 2 if rounded else 0.0
    out = [prim("plate", "box", (half_l, t / 2, half_h), (0, 0, z0 + half_h), material=mat)]
    if rounded:
        out.append(segment("edge", "capsule", (-half_l, 0, z0), (half_l, 0, z0), t / 2, mat))
    return out, _dims(thickness=t, half_length=half_l, half_height=half_h, edge_radius=z0), 1.0


def _ruler(rng: np.random.Generator) -> Built:
    half = (unif(rng, 0.075, 0.25), unif(rng, 0.0125, 0.02), unif(rng, 0.0008, 0.002))  # 15-50 cm
    mat, on_edge = pick(rng, _HARD), bool(rng.random() < 0.5)
    mat3 = rot("x", np.pi / 2) if on_edge else np.eye(3)
    dims = _dims(half_length=half[0], half_width=half[1], half_thickness=half[2], edge=on_edge)
    return [prim("ruler", "box", half, mat=mat3, material=mat)], dims, 1.0


def _mug(rng: np.random.Generator) -> Built:
    """Cylinder body, C-shaped handle of three capsules; standing, or lying rolled on its side."""
    r, h, rh = unif(rng, 0.035, 0.048), unif(rng, 0.04, 0.06), unif(rng, 0.005, 0.008)
    reach, span = unif(rng, 0.02, 0.03), unif(rng, 0.5, 0.7) * h
    mat = pick(rng, ("ceramic", "hard_plastic", "steel"))
    x0, x1 = r - rh, r + reach
    pts = [(x0, 0, span), (x1, 0, span), (x1, 0, -span), (x0, 0, -span)]
    out = [prim("body", "cylinder", (r, h), material=mat)]
    out += [segment(f"handle{i}", "capsule", pts[i], pts[i + 1], rh, mat) for i in range(3)]
    standing = bool(rng.random() < 0.3)
    roll = unif(rng, -np.pi, np.pi)
    pose = np.eye(3) if standing else rot("x", np.pi / 2) @ rot("z", roll)
    dims = _dims(radius=r, half_height=h, handle_radius=rh, handle_reach=reach, roll=roll)
    return rotate(out, pose), dims | {"standing": standing}, 0.25


def _screwdriver(rng: np.random.Generator) -> Built:
    """Handle and coaxial shaft; lying on its side or pressed with the handle's butt."""
    rh, hh = unif(rng, 0.012, 0.018), unif(rng, 0.04, 0.06)
    rs, hs = unif(rng, 0.0025, 0.004), unif(rng, 0.04, 0.08)
    grip = pick(rng, ("hard_plastic", "rubber", "wood"))
    out = [
        segment("handle", "cylinder", (-hh, 0, 0), (hh, 0, 0), rh, grip),
        segment("shaft", "cylinder", (hh, 0, 0), (hh + 2 * hs, 0, 0), rs, "steel"),
    ]
    butt = bool(rng.random() < 0.4)
    dims = _dims(handle_radius=rh, handle_half_length=hh, shaft_radius=rs, shaft_half_length=hs)
    return rotate(out, rot("y", np.pi / 2) if butt else np.eye(3)), dims | {"butt": butt}, 1.0


def _hammer(rng: np.random.Generator) -> Built:
    length, rh = unif(rng, 0.25, 0.33), unif(rng, 0.012, 0.017)
    head = (unif(rng, 0.012, 0.018), unif(rng, 0.045, 0.065), unif(rng, 0.012, 0.018))
    grip = pick(rng, ("wood", "rubber", "hard_plastic"))
    out = [
        segment("handle", "capsule", (0, 0, 0), (length, 0, 0), rh, grip),
        prim("head", "box", head, (length + head[0], 0, 0), material="steel"),
    ]
    out = rotate(out, rot("x", unif(rng, 0, np.pi / 2)))
    return out, _dims(length=length, handle_radius=rh, head_half_y=head[1]), 1.0


def _wrench(rng: np.random.Generator) -> Built:
    half_l, half_w, half_t = unif(rng, 0.06, 0.15), unif(rng, 0.006, 0.013), unif(rng, 0.003, 0.005)
    rh = unif(rng, 0.012, 0.02)
    out = [prim("shank", "box", (half_l, half_w, half_t), material="steel")]
    out += [
        prim(f"head{i}", "cylinder", (rh, half_t), (s * half_l, 0, 0), material="steel")
        for i, s in enumerate((-1, 1))
    ]
    return (
        out,
        _dims(half_length=half_l, half_width=half_w, half_thickness=half_t, head_radius=rh),
        1.0,
    )


def _finger_rows(rng: np.random.Generator, radii: np.ndarray) -> np.ndarray:
    """Centre offsets y (n,) m of parallel rods: gaps of 15-25 mm, >= 2 mm clear, centred."""
    gaps = [
        max(unif(rng, *FINGER_SPACING_M), radii[i] + radii[i + 1] + 0.002)
        for i in range(len(radii) - 1)
    ]
    y = np.concatenate([[0.0], np.cumsum(gaps)])
    return y - y.mean()


def _rake(rng: np.random.Generator) -> Built:
    """3-6 capsule tines on a crossbar (in their plane or raised), handle rising backwards."""
    n, r, length = int(rng.integers(3, 7)), unif(rng, *FINGER_RADIUS_M), unif(rng, 0.05, 0.10)
    y, mat = _finger_rows(rng, np.full(n, r)), pick(rng, (*_HARD, "rubber"))
    rb, lift = unif(rng, 0.008, 0.015), (0.0 if rng.random() < 0.5 else unif(rng, 0.005, 0.02))
    out = [
        segment(f"tine{i}", "capsule", (0, yi, r), (length, yi, r), r, mat)
        for i, yi in enumerate(y)
    ]
    zb = rb + lift
    out.append(segment("bar", "capsule", (-rb, y[0], zb), (-rb, y[-1], zb), rb, mat))
    a, lh = unif(rng, np.pi / 9, 2 * np.pi / 9), unif(rng, 0.15, 0.3)
    end = (-rb - lh * np.cos(a), 0, zb + lh * np.sin(a))
    out.append(segment("handle", "capsule", (-rb, 0, zb + rb), end, 0.012, mat))
    dims = _dims(
        n_tines=n,
        tine_radius=r,
        tine_length=length,
        spacing=float(np.diff(y).mean()),
        bar_radius=rb,
        bar_lift=lift,
    )
    return out, dims, 1.0


def _comb(rng: np.random.Generator) -> Built:
    """2-6 finger-wide box teeth (12-22 mm) joined by a spine that may touch or be raised."""
    n, w, length = int(rng.integers(2, 7)), unif(rng, 0.012, 0.022), unif(rng, 0.055, 0.09)
    ht, mat = unif(rng, 0.004, 0.01), pick(rng, ("wood", "hard_plastic", "rubber", "foam"))
    y = _finger_rows(rng, np.full(n, w / 2))
    out = [
        prim(f"tooth{i}", "box", (length / 2, w / 2, ht), (length / 2, yi, ht), material=mat)
        for i, yi in enumerate(y)
    ]
    hs, lift = unif(rng, 0.01, 0.02), (0.0 if rng.random() < 0.5 else unif(rng, 0.003, 0.01))
    half_y = (y[-1] - y[0] + w) / 2
    out.append(prim("spine", "box", (hs, half_y, ht), (-hs, 0, ht + lift), material=mat))
    dims = _dims(
        n_teeth=n,
        tooth_width=w,
        tooth_length=length,
        spacing=float(np.diff(y).mean()),
        spine_lift=lift,
    )
    return out, dims, 1.0


def _rod_bundle(rng: np.random.Generator) -> Built:
    """2-6 loose parallel rods of finger-like radius, uneven lengths and stagger, no connector."""
    n, shape = int(rng.integers(2, 7)), pick(rng, ("capsule", "cylinder"))
    radii = rng.uniform(*FINGER_RADIUS_M, size=n)
    y, mat = _finger_rows(rng, radii), pick(rng, _HARD + _SOFT)
    lengths, x0 = rng.uniform(0.05, 0.12, n), rng.uniform(-0.02, 0.02, n)
    dz = rng.uniform(0.0, 0.002, n)
    z = radii + dz
    out = [
        segment(
            f"rod{i}", shape, (x0[i], y[i], z[i]), (x0[i] + lengths[i], y[i], z[i]), radii[i], mat
        )
        for i in range(n)
    ]
    dims = _dims(
        n_rods=n,
        radius_mean=radii.mean(),
        length_mean=lengths.mean(),
        spacing=float(np.diff(y).mean()),
    )
    return out, dims | {"shape": shape}, 1.0


def _bottle(rng: np.random.Generator) -> Built:
    r, h = unif(rng, 0.03, 0.045), unif(rng, 0.07, 0.11)
    rn, hn = unif(rng, 0.012, 0.016), unif(rng, 0.02, 0.04)
    mat = pick(rng, ("hard_plastic", "ceramic", "aluminium"))
    out = [
        prim("body", "cylinder", (r, h), material=mat),
        prim("shoulder", "ellipsoid", (r, r, 0.6 * r), (0, 0, h), material=mat),
        prim("neck", "cylinder", (rn, hn), (0, 0, h + 0.5 * r + hn), material=mat),
    ]
    lying = bool(rng.random() < 0.7)
    pose = rot("y", np.pi / 2 + unif(rng, -0.1, 0.1)) if lying else np.eye(3)
    dims = _dims(radius=r, half_height=h, neck_radius=rn) | {"lying": lying}
    return rotate(out, pose), dims, 0.15


def _dumbbell(rng: np.random.Generator) -> Built:
    rh, hh = unif(rng, 0.014, 0.018), unif(rng, 0.05, 0.07)
    rp, tp = unif(rng, 0.035, 0.08), unif(rng, 0.01, 0.03)
    coat = pick(rng, ("steel", "rubber"))
    out = [segment("handle", "capsule", (-hh, 0, 0), (hh, 0, 0), rh, "steel")]
    out += [
        segment(f"weight{i}", "cylinder", (s * hh, 0, 0), (s * (hh + 2 * tp), 0, 0), rp, coat)
        for i, s in enumerate((-1, 1))
    ]
    return out, _dims(handle_radius=rh, half_length=hh, weight_radius=rp, weight_half=tp), 1.0


def _cushion(rng: np.random.Generator) -> Built:
    """Cushion, pillow or folded clothes: a padded slab 24-50 x 20-40 x 6-14 cm (an ellipsoid,
    bottom radius of curvature a^2 / c >= 0.2 m, so it lies flat over the link)."""
    semi = (unif(rng, 0.12, 0.25), unif(rng, 0.10, 0.20), unif(rng, 0.03, 0.07))
    dims = _dims(half_x=semi[0], half_y=semi[1], half_z=semi[2])
    return [prim("cushion", "ellipsoid", semi, material="padding")], dims, 1.0


def _big_ball(rng: np.random.Generator) -> Built:
    """Soft inflated ball: toy ball 24 cm to gym ball 65 cm across, about 0.3-2 kg."""
    r = unif(rng, 0.12, 0.33, log=True)
    return [prim("ball", "sphere", (r,), material="inflatable")], _dims(radius=r), 0.3


def _bundle(rng: np.random.Generator) -> Built:
    """A bag or bundle of clothes, towels or parcels: 3-5 padded lumps 12-24 cm across within
    +-8 cm of each other, bottoms up to 2 cm apart in height (an irregular broad print)."""
    n = int(rng.integers(3, 6))
    semi = rng.uniform((0.06, 0.06, 0.04), (0.12, 0.12, 0.07), (n, 3))
    xy, lift = rng.uniform(-0.08, 0.08, (n, 2)), rng.uniform(0.0, 0.02, n)
    out = [
        prim(f"lump{i}", "ellipsoid", semi[i], (*xy[i], semi[i, 2] + lift[i]), material="padding")
        for i in range(n)
    ]
    return out, _dims(n_lumps=n), 1.0


BUILDERS = {
    "ball": _ball,
    "box": _box,
    "cylinder_side": _cylinder_side,
    "cylinder_end": _cylinder_end,
    "plate": _plate,
    "plate_edge": _plate_edge,
    "ruler": _ruler,
    "mug": _mug,
    "screwdriver": _screwdriver,
    "hammer": _hammer,
    "wrench": _wrench,
    "rake": _rake,
    "comb": _comb,
    "rod_bundle": _rod_bundle,
    "bottle": _bottle,
    "dumbbell": _dumbbell,
    "cushion": _cushion,
    "big_ball": _big_ball,
    "bundle": _bundle,
}
HARD_NEGATIVES: tuple[str, ...] = ("rake", "comb", "rod_bundle")
OBJECT_KINDS: tuple[str, ...] = tuple(BUILDERS)


def build_object(
    kind: str,
    rng: np.random.Generator | None,
    instance_id: int | None = None,
) -> ContactorSpec:
    """Object contactor ``kind`` (one of `OBJECT_KINDS`), instance ``instance_id``.

    The instance depends only on (kind, instance_id); ``rng`` only draws the id when it is None
    (from 0..999). KeyError-like ConfigError lists the kinds.
    """
    if kind not in BUILDERS:
        raise ConfigError(f"unknown object kind {kind!r}; known kinds: {', '.join(BUILDERS)}")
    if instance_id is None:
        instance_id = int(rng.integers(1000))
    irng = instance_rng(kind, instance_id)
    prims, dims, fill = BUILDERS[kind](irng)
    return assemble(
        prims,
        "object",
        kind,
        instance_id,
        dims=dims,
        compliance=draw_compliance(irng, prims),
        fill=fill,
    )


# --- how objects are pressed -------------------------------------------------------------------


# Forces span those of the hand interactions (subjects press 0.5-2x a nominal 5-20 N, root
# limit 40 N) so that force, hence area and intensity, is no shortcut: an object held against
# the arm 5-40 N (comfortable one-handed pushes are tens of N); resting = its weight up to a
# light push, 1-15 N; a bump is short and firm, 10-40 N.
OBJECT_MODES: dict[str, tuple[float, PressMode]] = {  # mode: (probability, ranges)
    "pressed": (0.35, PressMode((5.0, 40.0), (0.0, 0.08))),
    "tilted": (0.2, PressMode((3.0, 30.0), (0.15, 0.4))),
    "resting": (0.2, PressMode((1.0, 15.0), (0.0, 0.05), durations_s=(0.2, 0.3, 0.5, 0.2))),
    "bumped": (0.1, PressMode((10.0, 40.0), (0.0, 0.2), (0.0, 3.0), (0.08, 0.08, 0.1, 0.1))),
    "slid": (0.15, PressMode((5.0, 30.0), (0.0, 0.1), (1.0, 10.0))),
}

# Parallel rods along the link touch with one rod only (the tube falls away ~y^2 / 2R, 2.7 mm
# at 20 mm off the top); across it every rod touches, like the fingers of a grasp.
ACROSS_FRACTION, ACROSS_SD_RAD = 0.7, 0.25


def object_press(spec: ContactorSpec, rng: np.random.Generator) -> tuple[str, PressPlan]:
    """(mode, plan) for an object: resting forces are its weight (9.81 m/s^2) up to 15 N; hard
    negatives mostly lie across the link (`ACROSS_FRACTION`), as fingers do in a grasp."""
    mode = draw_mode(rng, OBJECT_MODES)
    plan = plan_from_mode(rng, OBJECT_MODES[mode][1])
    if spec.name in HARD_NEGATIVES and rng.random() < ACROSS_FRACTION:
        across = np.pi / 2 * np.sign(rng.uniform(-1, 1)) + rng.normal(0.0, ACROSS_SD_RAD)
        plan = replace(plan, yaw_rad=float(across))
    if mode == "resting":
        weight_n = 9.81 * float(spec.description.get("mass_kg", 0.1))
        force = float(np.clip(weight_n * unif(rng, 1.0, 2.0), 1.0, 15.0))
        plan = replace(plan, force_n=force)
    return mode, plan


def plan_object_press(spec: ContactorSpec, rng: np.random.Generator) -> PressPlan:
    """How object ``spec`` is pressed: pressed flat, tilted, resting, bumped or slid (see
    `OBJECT_MODES`); forces in N, angles in rad."""
    return object_press(spec, rng)[1]
