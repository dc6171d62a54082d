"""Object contactors: compile and press on the forearm, published sizes, determinism, primitives,
hard negatives, press plans."""

from __future__ import annotations

import json

import mujoco
import numpy as np
import pytest

from sim.contactors.objects import (
    HARD_NEGATIVES,
    OBJECT_KINDS,
    OBJECT_MODES,
    build_object,
    object_press,
    plan_object_press,
)
from sim.contactors.primitives import FINGER_RADIUS_M, FINGER_SPACING_M, MATERIALS
from sim.contactors.spec import PressPlan
from sim.episode import press
from sim.skin.parts import get_part
from sim.skin.readout import SDF, signed_distance
from tactile.errors import ConfigError

PRIMITIVES = {int(t) for t in SDF}


def skin_frame(part, k: int):
    """Skin frame (pos (3,), quat (4,)) at taxel k: z outward normal, x along the link (+z)."""
    z = part.layout.normals[k]
    x = np.array([0.0, 0.0, 1.0]) - z[2] * z
    x /= np.linalg.norm(x)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.column_stack([x, np.cross(z, x), z]).ravel())
    return part.layout.positions_m[k], quat


def press_for(contactor, plan: PressPlan, seconds: float = 1.0):
    """Press on the forearm's middle band for ``seconds``; (max depth (N,) m, warnings)."""
    part = get_part("forearm")
    scene = press.build_press_scene(part, contactor, 0.002)
    k = int(np.argmin(np.linalg.norm(part.flat_mm - np.median(part.flat_mm, axis=0), axis=1)))
    press.reset(scene, plan, *skin_frame(part, k))
    deepest = np.zeros(part.n_taxels)
    for _ in range(round(seconds / 0.01)):
        press.apply_controls(scene, plan, scene.data.time)
        mujoco.mj_step(scene.model, scene.data, nstep=5)
        deepest = np.maximum(deepest, scene.readout.depth_m(scene.data))
    warnings = {i: w.number for i, w in enumerate(scene.data.warning) if w.number}
    return deepest, warnings


@pytest.mark.parametrize("kind", OBJECT_KINDS)
def test_object_presses_forearm_without_warnings(kind: str) -> None:
    c = build_object(kind, None, 0)
    plan = PressPlan(force_n=20.0, yaw_rad=np.pi / 2, durations_s=(0.2, 0.3, 0.5, 0.0))
    depth, warnings = press_for(c, plan)
    assert not warnings
    assert depth.max() > 0, "no taxel read any depth"
    assert depth.max() < c.max_penetration_m


@pytest.mark.parametrize("kind", OBJECT_KINDS)
def test_geoms_are_primitives_labelled_zero(kind: str) -> None:
    c = build_object(kind, None, 5)
    model = c.spec.compile()
    collide = [i for i in range(model.ngeom) if model.geom_contype[i]]
    assert sorted(model.geom(i).name for i in collide) == sorted(c.geom_labels)
    assert all(int(model.geom_type[i]) in PRIMITIVES for i in collide)
    assert set(c.geom_labels.values()) == {0}
    assert c.kind == "object" and c.instance_id == 5 and c.subject_id == -1
    assert c.description["mass_kg"] > 0
    json.dumps(c.description)


@pytest.mark.parametrize("kind", OBJECT_KINDS)
def test_lowest_point_is_the_root_plane(kind: str) -> None:
    """Independent check with the readout's signed distances: nothing below z = 0, touching it."""
    model = build_object(kind, None, 2).spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    g = np.linspace(-0.35, 0.35, 141)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    below = np.column_stack([xy, np.full(len(xy), -3e-4)])
    above = np.column_stack([xy, np.full(len(xy), 3e-4)])
    sd = [
        (
            signed_distance(
                model.geom_type[i], model.geom_size[i], data.geom_xpos[i], data.geom_xmat[i], below
            ).min(),
            signed_distance(
                model.geom_type[i], model.geom_size[i], data.geom_xpos[i], data.geom_xmat[i], above
            ).min(),
        )
        for i in range(model.ngeom)
    ]
    assert min(s[0] for s in sd) > 0
    assert min(s[1] for s in sd) < 6e-4  # within the grid step's reach of the surface


@pytest.mark.parametrize("kind", OBJECT_KINDS)
def test_instances_are_deterministic(kind: str) -> None:
    a, b = build_object(kind, None, 7), build_object(kind, np.random.default_rng(3), 7)
    assert a.spec.to_xml() == b.spec.to_xml() and a.description == b.description
    assert build_object(kind, None, 8).description != a.description


# Published sizes of the balls sim/contactors/objects.py draws between: ITTF, The Laws of Table
# Tennis 2.3.1, "the ball shall be spherical, with a diameter of 40mm"; IFAB, Laws of the Game, Law
# 2, a football's circumference is 68-70 cm.
TABLE_TENNIS_BALL_RADIUS_M = 0.040 / 2
FOOTBALL_RADIUS_M = 0.70 / (2 * np.pi)  # the largest football, 111.4 mm


def test_balls_range_from_a_table_tennis_ball_to_a_football() -> None:
    radii = [build_object("ball", None, i).description["dimensions_m"]["radius"] for i in range(60)]
    assert min(radii) >= TABLE_TENNIS_BALL_RADIUS_M - 1e-5  # dimensions are rounded to 10 um
    assert max(radii) <= FOOTBALL_RADIUS_M


@pytest.mark.parametrize("kind", OBJECT_KINDS)
def test_compliance_within_each_materials_range(kind: str) -> None:
    for i in range(10):
        stiffness = build_object(kind, None, i).description["stiffness"]
        for material, depth in stiffness["compliance_depth_m"].items():
            lo, hi = MATERIALS[material][1]
            assert lo <= depth <= hi, (material, depth)


def parallel_rods(model: mujoco.MjModel) -> tuple[np.ndarray, np.ndarray]:
    """Centre offsets (K,) m across the rods and their half-widths (K,) m, for the elongated
    geoms parallel to the most common long axis."""
    axes, offsets, widths = [], [], []
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    for i in range(model.ngeom):
        size, mat = model.geom_size[i], data.geom_xmat[i].reshape(3, 3)
        if model.geom_type[i] == mujoco.mjtGeom.mjGEOM_BOX:
            k = int(np.argmax(size))
            side = min((j for j in range(3) if j != k), key=lambda j: abs(mat[2, j]))
            long, half_w = 2 * size[k], size[side]  # width: the horizontal short side
        else:
            k, long, half_w = 2, 2 * size[1], size[0]
        if long >= 2.5 * 2 * half_w:
            axes.append(mat[:, k])
            offsets.append(data.geom_xpos[i])
            widths.append(half_w)
    axis = axes[0]
    keep = [j for j, a in enumerate(axes) if abs(a @ axis) > 0.999]
    across = np.cross(axis, [0.0, 0.0, 1.0])
    return np.array(offsets)[keep] @ across, np.array(widths)[keep]


@pytest.mark.parametrize("kind", HARD_NEGATIVES)
def test_hard_negatives_have_finger_like_parallel_rods(kind: str) -> None:
    """Measured on the compiled model: the rods' spacing and half-width are the finger spacing and
    phalanx radii that `sim.contactors.primitives` declares (those of
    `sim.contactors.hand_kinematics`' hands)."""
    for i in range(10):
        y, half_w = parallel_rods(build_object(kind, None, i).spec.compile())
        assert len(y) >= 2
        order = np.argsort(y)
        spacing = np.diff(y[order])
        (r_lo, r_hi), (s_lo, s_hi) = FINGER_RADIUS_M, FINGER_SPACING_M
        assert np.all((spacing > s_lo - 1e-6) & (spacing < s_hi + 1e-6)), spacing
        assert np.all((half_w >= r_lo - 1e-6) & (half_w <= r_hi + 1e-6)), half_w


def test_press_plans_follow_their_modes() -> None:
    rng = np.random.default_rng(0)
    for i in range(200):
        c = build_object(OBJECT_KINDS[i % len(OBJECT_KINDS)], None, i)
        mode, plan = object_press(c, rng)
        lo, hi = OBJECT_MODES[mode][1].force_n
        assert lo - 1e-9 <= plan.force_n <= hi + 1e-9
        assert np.hypot(*plan.tilt_rad) <= OBJECT_MODES[mode][1].tilt_rad[1] + 1e-9
        assert plan.action == -1 and plan.operator_position == -1 and plan.site_uv is None
    assert isinstance(plan_object_press(c, rng), PressPlan)


def test_unknown_kind_lists_the_known() -> None:
    with pytest.raises(ConfigError, match="known kinds: ball"):
        build_object("spoon", None, 0)
    with pytest.raises(ConfigError, match="instance_id"):
        build_object("ball", None, -2)
