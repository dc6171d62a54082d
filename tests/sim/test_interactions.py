"""Hand contactor and interaction plans: labels, directions by action, force scaling, and
attribution of pressed taxels to the nearest hand geom (checked with an independent distance)."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from sim.contactors.hand import HAND_PARTS
from sim.contactors.interactions import hand_contactor, plan_hand_interaction
from sim.contactors.spec import ACTIONS, OPERATOR_POSITIONS, ROOT
from sim.contactors.subjects import sample_subjects
from sim.episode.runner import EpisodeContext, run_episode
from sim.skin.parts import get_part

SUBJECTS = sample_subjects(3, np.random.default_rng(4))


@pytest.fixture(scope="module")
def ctx() -> EpisodeContext:
    return EpisodeContext()


def test_hand_contactor_labels_every_part_and_has_a_bare_root():
    c = hand_contactor(SUBJECTS[0])
    assert set(c.geom_labels.values()) == set(range(1, len(HAND_PARTS) + 1))
    assert len(c.spec.body(ROOT).joints) == 0
    assert not [j for j in c.spec.joints if "root_" in j.name]
    assert c.kind == "hand" and c.subject_id == 0
    assert c.max_penetration_m > SUBJECTS[0].tissue_depth_m


@pytest.mark.parametrize("action", ACTIONS)
def test_plan_directions_follow_the_action(action):
    part = get_part("forearm")
    for pos in ("front", "side") if action != "free" else ("free",):
        plan = plan_hand_interaction(action, pos, SUBJECTS[1], part, np.random.default_rng(0))
        assert ACTIONS[plan.action] == action and OPERATOR_POSITIONS[plan.operator_position] == pos
        distal = np.array([np.cos(plan.yaw_rad), np.sin(plan.yaw_rad)])
        left = np.array([-distal[1], distal[0]])
        shear = np.asarray(plan.shear_n)
        expected = {"push_away": distal, "pull": -distal, "push_left": left, "push_right": -left}
        if action in expected:
            assert shear @ expected[action] == pytest.approx(np.linalg.norm(shear))
            assert 0 < np.linalg.norm(shear) < plan.force_n
        twist = {"grasp_twist_cw": -1, "grasp_twist_ccw": 1}.get(action, 0)
        assert np.sign(plan.twist_nm) == twist


def test_front_puts_fingers_across_the_link_and_side_along_it():
    part = get_part("forearm")
    rng = np.random.default_rng(1)
    front = [
        plan_hand_interaction("push_away", "front", SUBJECTS[2], part, rng).yaw_rad
        for _ in range(20)
    ]
    side = [
        plan_hand_interaction("push_away", "side", SUBJECTS[2], part, rng).yaw_rad
        for _ in range(20)
    ]
    assert np.median(np.abs(np.sin(front))) > 0.85  # hand x across the link axis
    assert np.median(np.abs(np.cos(side))) > 0.85  # hand x along it


def test_force_scales_with_the_subject():
    part = get_part("forearm")
    weak = dataclasses.replace(SUBJECTS[0], force_scale=0.5)
    strong = dataclasses.replace(SUBJECTS[0], force_scale=2.0)
    f = [
        plan_hand_interaction("grasp", "front", s, part, np.random.default_rng(3)).force_n
        for s in (weak, strong)
    ]
    assert f[1] / f[0] == pytest.approx(4.0)


def reference_distance(model: mujoco.MjModel, data: mujoco.MjData, geom: int, p: np.ndarray):
    """Signed distance (m) of point p to a capsule or box geom, written independently."""
    local = data.geom_xmat[geom].reshape(3, 3).T @ (p - data.geom_xpos[geom])
    size = model.geom_size[geom]
    if model.geom_type[geom] == mujoco.mjtGeom.mjGEOM_CAPSULE:
        axial = np.clip(local[2], -size[1], size[1])
        return float(np.linalg.norm(local - [0, 0, axial]) - size[0])
    q = np.abs(local) - size
    return float(np.linalg.norm(np.maximum(q, 0)) + min(q.max(), 0))


def pressed_hand(ctx, subject, action: str):
    """The first seeded episode whose last frame presses at least 5 taxels."""
    contactor = hand_contactor(subject)
    for seed in range(10):
        rng = np.random.default_rng(seed)
        plan = plan_hand_interaction(action, "front", subject, ctx.part, rng)
        last = run_episode(ctx, contactor, plan, np.random.default_rng(seed)).frames[-1]
        if (last.geom >= 0).sum() >= 5:
            return ctx.scene(contactor), last
    raise AssertionError("no seeded episode pressed the skin")


@pytest.mark.parametrize("action", ["push_away", "grasp"])
def test_attribution_names_the_nearest_hand_geom(ctx, action):
    scene, last = pressed_hand(ctx, SUBJECTS[0], action)
    m, d = scene.model, scene.data
    pressed = np.flatnonzero(last.geom >= 0)
    positions = scene.readout.positions_m(d, pressed)
    for taxel, p in zip(pressed, positions, strict=True):
        dist = [reference_distance(m, d, g, p) for g in scene.readout.geoms]
        assert int(np.argmin(dist)) == last.geom[taxel]
        assert scene.geom_label[int(np.argmin(dist))] == last.geom_label[taxel]
