"""The procedural hand: anthropometry, mirroring, labels, opposition, arch, stability, softness."""

from __future__ import annotations

import re
from pathlib import Path

import mujoco
import numpy as np
import pytest

from sim.contactors.hand import (
    HAND_PARTS,
    METACARPAL_SHAFT,
    TISSUE_RATIO,
    HandConfig,
    apply_pose,
    build_hand_spec,
    geom_part_ids,
    geom_parts,
    set_hand_options,
)
from tactile.errors import ConfigError

SIDES = ("right", "left")
SCENE = "s0_"  # attach prefix (a subject's); an empty prefix makes MuJoCo log a warning
PLATE_RES = 160  # tactile plate vertices per side
PLATE_HALF_M = 0.04  # half-size of the tactile plate, m


def scene(cfg: HandConfig, *, floor: bool = False, plate: bool = False, z_m: float = 0.1):
    """Compiled (model, data): the hand attached to a frame at height ``z_m``."""
    spec = mujoco.MjSpec()
    set_hand_options(spec)
    if floor:
        spec.worldbody.add_geom(name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[1, 1, 0.1])
    if plate:
        add_tactile_plate(spec)
    frame = spec.worldbody.add_frame(pos=[0, 0, z_m])
    spec.attach(build_hand_spec(cfg), frame=frame, prefix=SCENE)
    model = spec.compile()
    return model, mujoco.MjData(model)


def add_tactile_plate(spec: mujoco.MjSpec) -> None:
    """MuJoCo tactile sensor on a fine plate lying on the floor (z = 0, facing +z)."""
    mesh = spec.add_mesh(name="plate", scale=[PLATE_HALF_M, PLATE_HALF_M, 0.001])
    mesh.make_plate([PLATE_RES, PLATE_RES])
    spec.worldbody.add_geom(
        name="plate",
        type=mujoco.mjtGeom.mjGEOM_MESH,
        meshname="plate",
        contype=0,
        conaffinity=0,
        pos=[0, 0, 0.001],  # the builtin plate sits 1 mm (scale z) below its frame
    )
    spec.add_sensor(
        name="tactile",
        type=mujoco.mjtSensor.mjSENS_TACTILE,
        objtype=mujoco.mjtObj.mjOBJ_MESH,
        objname="plate",
        reftype=mujoco.mjtObj.mjOBJ_GEOM,
        refname="plate",
    )


def pre(cfg: HandConfig) -> str:
    """Prefix of the hand's elements in the test scene, e.g. ``s0_rh_``."""
    return SCENE + cfg.prefix


def set_joint(model, data, name: str, value: float) -> None:
    """Set a joint's qpos and its actuator's target."""
    data.qpos[model.jnt_qposadr[model.joint(name).id]] = value
    data.ctrl[model.actuator(name).id] = value


def no_warnings(data) -> bool:
    return all(data.warning[i].number == 0 for i in range(int(mujoco.mjtWarning.mjNWARNING)))


# --- configuration -----------------------------------------------------------------------------


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"length_m": 0.14}, "length_m"),
        ({"length_m": 0.23}, "length_m"),
        ({"length_m": 0.18, "breadth_m": 0.05}, "breadth_m"),
        ({"side": "middle"}, "side"),
        ({"tissue_depth_m": 0.02}, "tissue_depth_m"),
        ({"strength": 0.0}, "strength"),
    ],
)
def test_config_out_of_range_names_the_field(kwargs, field):
    with pytest.raises(ConfigError, match=field):
        HandConfig(**kwargs)


def test_default_breadth_and_prefix():
    cfg = HandConfig(length_m=0.20, side="left")
    assert cfg.breadth_m == pytest.approx(0.09)
    assert cfg.prefix == "lh_"


# --- anthropometry -----------------------------------------------------------------------------


def anthropometry_table(readme: Path) -> dict[str, list[float | None]]:
    """The Buchholz table of ../shared/data/README.md: digit -> 4 fractions (None for '—')."""
    rows = {}
    for line in readme.read_text().splitlines():
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        if len(cells) == 5 and cells[0] in ("thumb", "index", "middle", "ring", "little"):
            digit = "pinkie" if cells[0] == "little" else cells[0]
            rows[digit] = [None if re.fullmatch(r"[—-]", c) else float(c) for c in cells[1:]]
    return rows


def measured_lengths(model, data, p: str, digit: str) -> list[float | None]:
    """(metacarpal, proximal, middle, distal) lengths measured on the compiled model, m."""
    pos = lambda name: data.body(p + name).xpos  # noqa: E731
    tip = data.site(f"{p}{digit}_tip").xpos
    if digit == "thumb":
        meta = np.linalg.norm(pos("thumb_proximal") - pos("thumb_metacarpal"))
        prox = np.linalg.norm(pos("thumb_distal") - pos("thumb_proximal"))
        return [meta, prox, None, np.linalg.norm(tip - pos("thumb_distal"))]
    head = 2 * model.geom_size[model.geom(f"{p}palm_{digit}_metacarpal").id, 1]
    meta = head / (1.0 - METACARPAL_SHAFT)  # the capsule covers the head end of the bone
    prox = np.linalg.norm(pos(f"{digit}_middle") - pos(f"{digit}_proximal"))
    mid = np.linalg.norm(pos(f"{digit}_distal") - pos(f"{digit}_middle"))
    return [meta, prox, mid, np.linalg.norm(tip - pos(f"{digit}_distal"))]


@pytest.mark.parametrize("length_m", [0.15, 0.22])
def test_segment_lengths_match_anthropometry_table(shared_data, length_m):
    table = anthropometry_table(shared_data / "README.md")
    assert set(table) == {"thumb", "index", "middle", "ring", "pinkie"}
    model, data = scene(HandConfig(length_m=length_m))
    mujoco.mj_kinematics(model, data)
    for digit, fractions in table.items():
        got = measured_lengths(model, data, "s0_rh_", digit)
        for frac, value in zip(fractions, got, strict=True):
            assert (frac is None) == (value is None)
            if frac is not None:
                assert value == pytest.approx(frac * length_m, abs=1e-6), digit
    tip = data.site("s0_rh_middle_tip").xpos - data.body("s0_rh_palm").xpos
    assert tip[0] == pytest.approx(length_m, abs=1e-6)  # hand length = crease to middle tip


# --- mirroring and labels ----------------------------------------------------------------------


@pytest.mark.parametrize("pose", ["open", "fist", "pinch"])
def test_left_hand_is_the_mirror_of_the_right(pose):
    mirror = np.array([1.0, -1.0, 1.0])
    (mr, dr), (ml, dl) = scene(HandConfig(side="right")), scene(HandConfig(side="left"))
    apply_pose(mr, dr, pose, "s0_rh_")
    apply_pose(ml, dl, pose, "s0_lh_")
    for digit in ("thumb", "index", "middle", "ring", "pinkie"):
        right, left = dr.site(f"s0_rh_{digit}_tip").xpos, dl.site(f"s0_lh_{digit}_tip").xpos
        np.testing.assert_allclose(left, right * mirror, atol=1e-9)
    assert mr.ngeom == ml.ngeom
    np.testing.assert_allclose(dl.geom_xpos, dr.geom_xpos * mirror, atol=1e-9)


@pytest.mark.parametrize("side", SIDES)
def test_every_collision_geom_has_a_part_tag(side):
    cfg = HandConfig(side=side)
    spec = build_hand_spec(cfg)
    parts = geom_parts(spec)
    colliding = [g.name for g in spec.geoms if g.contype or g.conaffinity]
    assert sorted(parts) == sorted(colliding)
    assert set(parts.values()) == set(HAND_PARTS)
    model, _ = scene(cfg)
    ids = geom_part_ids(model)
    for name, part in parts.items():
        assert ids[model.geom(SCENE + name).id] == HAND_PARTS.index(part) + 1
    assert (ids > 0).sum() == len(parts)


def test_coarse_palm_drops_the_rounding_capsules_and_keeps_every_part():
    """Coarse detail: per palm half, the two metacarpal capsules and the heel capsule go (6 geoms)
    and nothing else changes — the same parts, joints, actuators and finger geoms."""
    full, coarse = (build_hand_spec(HandConfig(detail=d)) for d in ("full", "coarse"))
    pf, pc = geom_parts(full), geom_parts(coarse)
    gone = sorted(set(pf) - set(pc))
    assert set(pc) <= set(pf) and len(gone) == 6
    assert all(pf[g] == "palm" and ("metacarpal" in g or "heel" in g) for g in gone)
    assert set(pc.values()) == set(HAND_PARTS)
    assert [j.name for j in full.joints] == [j.name for j in coarse.joints]
    assert len(full.actuators) == len(coarse.actuators)
    with pytest.raises(ConfigError, match="detail='fine' unknown"):
        HandConfig(detail="fine")


# --- thumb opposition and palm arch ------------------------------------------------------------


@pytest.mark.parametrize("side", SIDES)
def test_thumb_opposes_index_and_middle(side):
    """In the pinch pose (all joints inside their limits) the thumb tip meets the fingertips."""
    cfg = HandConfig(side=side)
    model, data = scene(cfg)
    apply_pose(model, data, "open", pre(cfg))
    tip = lambda d: data.site(f"{pre(cfg)}{d}_tip").xpos.copy()  # noqa: E731
    assert np.linalg.norm(tip("thumb") - tip("index")) > 0.06
    apply_pose(model, data, "pinch", pre(cfg))
    inside = (data.qpos[model.jnt_qposadr] >= model.jnt_range[:, 0] - 1e-9) | ~model.jnt_limited
    assert np.all(
        inside
        & ((data.qpos[model.jnt_qposadr] <= model.jnt_range[:, 1] + 1e-9) | ~model.jnt_limited)
    )
    gap = min(np.linalg.norm(tip("thumb") - tip(f)) for f in ("index", "middle"))
    assert gap < 0.02
    palm_z = data.site(f"{pre(cfg)}palm_center").xpos[2]
    assert tip("thumb")[2] < palm_z  # the thumb crossed to the palmar side


def test_palm_arches():
    model, data = scene(HandConfig())
    joint = model.joint("s0_rh_palm_arch")
    assert joint.range[1] > np.deg2rad(15)
    normal = lambda g: data.geom_xmat[model.geom(g).id].reshape(3, 3)[:, 2].copy()  # noqa: E731
    mujoco.mj_kinematics(model, data)
    pinkie_z0 = data.body("s0_rh_pinkie_proximal").xpos[2]
    halves = lambda: normal("s0_rh_palm_radial_pad") @ normal("s0_rh_palm_ulnar_pad")  # noqa: E731
    angle0 = np.arccos(np.clip(halves(), -1, 1))
    set_joint(model, data, "s0_rh_palm_arch", joint.range[1])
    mujoco.mj_kinematics(model, data)
    angle1 = np.arccos(np.clip(halves(), -1, 1))
    assert angle0 == pytest.approx(0.0, abs=1e-6)
    assert angle1 == pytest.approx(joint.range[1], abs=1e-6)
    assert data.body("s0_rh_pinkie_proximal").xpos[2] < pinkie_z0 - 0.005  # cupped towards the palm


# --- dynamics ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("side", "length_m", "detail"),
    [
        ("right", 0.15, "full"),
        ("right", 0.22, "full"),
        ("left", 0.15, "full"),
        ("left", 0.22, "full"),
        ("right", 0.18, "coarse"),
    ],
)
def test_steps_one_second_under_random_controls_without_warnings(side, length_m, detail):
    cfg = HandConfig(length_m=length_m, side=side, detail=detail)
    model, data = scene(cfg, floor=True, z_m=0.06)
    rng = np.random.default_rng(7)
    lo, hi = model.actuator_ctrlrange.T
    for step in range(round(1.0 / model.opt.timestep)):
        if step % 25 == 0:
            data.ctrl[:] = rng.uniform(lo, hi)
            data.ctrl[:3] = rng.uniform(-0.03, 0.03, 3)  # root slides: stay near the floor
            data.ctrl[3:6] = rng.uniform(-0.5, 0.5, 3)
        mujoco.mj_step(model, data)
    assert no_warnings(data)
    assert np.all(np.isfinite(data.qpos))


@pytest.mark.parametrize("side", SIDES)
def test_fingers_close_around_a_cylinder_and_stop_on_it(side):
    """Fingers driven towards a fist wrap a fixed 7 cm-radius cylinder without passing into it."""
    radius_m = 0.07
    cfg = HandConfig(side=side)
    spec = mujoco.MjSpec()
    set_hand_options(spec)
    spec.worldbody.add_geom(
        name="cylinder",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[radius_m, 0.15, 0],
        quat=[np.cos(np.pi / 4), np.sin(np.pi / 4), 0, 0],  # axis along y: fingers wrap over it
    )
    palm_r = 0.13 * cfg.breadth_m
    frame = spec.worldbody.add_frame(pos=[-0.35 * cfg.length_m, 0, radius_m + palm_r + 1e-3])
    spec.attach(build_hand_spec(cfg), frame=frame, prefix=SCENE)
    model = spec.compile()
    data = mujoco.MjData(model)
    apply_pose(model, data, "open", pre(cfg))
    set_joint(model, data, f"{pre(cfg)}root_z", -0.005)  # rest the palm on the cylinder
    data.qpos[model.jnt_qposadr[model.joint(f"{pre(cfg)}root_z").id]] = 0.0
    probe = mujoco.MjData(model)
    apply_pose(model, probe, "fist", pre(cfg))  # fist targets of the finger actuators
    data.ctrl[6:] = probe.ctrl[6:]
    for _ in range(500):
        mujoco.mj_step(model, data)
    assert no_warnings(data)
    cyl = model.geom("cylinder").id
    parts = geom_part_ids(model)
    touching, depth = set(), 0.0
    for c in data.contact[: data.ncon]:
        if cyl in c.geom:
            other = c.geom[1] if c.geom[0] == cyl else c.geom[0]
            touching.add(HAND_PARTS[parts[other] - 1])
            depth = max(depth, -c.dist)
    assert {"index", "middle", "ring", "palm"} <= touching
    assert depth < max(TISSUE_RATIO.values()) * cfg.tissue_depth_m  # per-segment allowances
    mcp = f"{pre(cfg)}middle_mcp_flex"
    angle = data.qpos[model.jnt_qposadr[model.joint(mcp).id]]
    assert angle < data.ctrl[model.actuator(mcp).id] - 0.1  # stopped on the cylinder


def press_index_fingertip(cfg: HandConfig, force_n: float) -> tuple[float, float, float]:
    """Press the index pad on a tactile plate with ``force_n``; (depth, width, radius), m."""
    cfg = HandConfig(**{**cfg.__dict__, "root_force_n": force_n})
    model, data = scene(cfg, floor=True, plate=True, z_m=0.08)
    p = pre(cfg)
    set_joint(model, data, f"{p}root_ry", 0.6)  # pitch the fingers down
    for finger in ("middle", "ring", "pinkie"):
        set_joint(model, data, f"{p}{finger}_mcp_flex", -0.5)
    for joint in ("index_mcp_flex", "index_pip"):
        set_joint(model, data, f"{p}{joint}", 0.3)
    set_joint(model, data, f"{p}thumb_cmc_abd", -0.15)
    mujoco.mj_kinematics(model, data)
    tip = data.site(f"{p}index_tip").xpos.copy()
    for axis in (0, 1):  # centre the pad over the plate
        set_joint(model, data, f"{p}root_{'xy'[axis]}", -tip[axis])
    data.ctrl[model.actuator(f"{p}root_z").id] = -0.2  # far below: the force saturates
    for _ in range(600):
        mujoco.mj_step(model, data)
    assert no_warnings(data)
    return fingertip_depth_and_width(model, data, p)


def fingertip_depth_and_width(model, data, p: str) -> tuple[float, float, float]:
    """(deepest contact, touched width across the finger, fingertip radius) of the index, m."""
    tip = model.geom(f"{p}index_distal").id
    depths = [-c.dist for c in data.contact[: data.ncon] if tip in c.geom]
    assert depths, "the index fingertip does not touch the plate"
    n = model.mesh_vertnum[0]
    plate = model.geom("plate").id
    world = model.mesh_vert[:n] @ data.geom_xmat[plate].reshape(3, 3).T + data.geom_xpos[plate]
    touched = world[data.sensordata[:n] > 0]
    step = 2 * PLATE_HALF_M / PLATE_RES
    return max(depths), float(np.ptp(touched[:, 1]) + step), float(model.geom_size[tip, 0])


@pytest.mark.parametrize("length_m", [0.15, 0.18, 0.22])
@pytest.mark.parametrize("force_n", [2.0, 5.0])
def test_fingertip_contact_patch_is_10_to_15_mm_at_moderate_force(length_m, force_n):
    # a pressed finger pad touches about 10-15 mm across at moderate force (the issue's spec);
    # the pulp's allowance is TISSUE_RATIO["distal"] x tissue_depth_m (sim.contactors.hand), so the
    # capsule end sinks 2.5-3 mm
    # strongest servos: the finger holds its pose, so the patch measures the tissue alone (at
    # strength 1 the compliant index yields at 5 N and the palm reaches the plate)
    cfg = HandConfig(length_m=length_m, strength=4.0)
    depth, width, radius = press_index_fingertip(cfg, force_n)
    assert 0.0005 < depth < TISSUE_RATIO["distal"] * cfg.tissue_depth_m
    assert 0.010 <= width <= 0.015
    # the plate's measure agrees with the chord of a capsule end at that depth (1 grid step)
    assert width == pytest.approx(2 * np.sqrt(2 * radius * depth - depth**2), abs=0.0015)
