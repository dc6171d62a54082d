"""Finger spread: each subject's habitual MCP abduction, fanned, held from before the hand lands;
the thumb opened likewise in whole-hand touches."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from sim.contactors.hand_kinematics import FINGERS, JOINT_LIMITS_DEG
from sim.contactors.interaction_poses import (
    MCP_REACHED,
    THUMB_SPREAD_DEG,
    finger_pose,
    finger_spread,
    thumb_spread,
)
from sim.contactors.interactions import hand_contactor, joint_name, plan_hand_interaction
from sim.contactors.spec import PressPlan
from sim.contactors.subjects import FINGER_SPREAD_RANGE_DEG, Subject, sample_subjects
from sim.episode import press
from sim.episode.runner import CONTROL_DT_S, EpisodeContext, run_episode, site_pose
from tactile.errors import ConfigError

SUBJECT = sample_subjects(1, np.random.default_rng(4))[0]


def still(subject: Subject, spread_deg: float) -> Subject:
    """``subject`` with no pose noise and the habitual spread ``spread_deg`` (degrees)."""
    return dataclasses.replace(subject, pose_noise_deg=0.0, finger_spread_deg=spread_deg)


def test_spread_fans_the_fingers_by_the_habit_times_the_cosine_of_mcp_flexion_reached():
    flex_deg = {"index": 0.0, "middle": 30.0, "ring": 70.0, "pinkie": 95.0}
    targets = {f"{f}_mcp_flex": np.deg2rad(v) for f, v in flex_deg.items()}
    got = finger_spread(still(SUBJECT, 6.0), targets, np.random.default_rng(0))
    # index 1 x, middle 0 x, ring 1 x, pinkie 2 x the spread, by the cosine of the flexion reached
    # (MCP_REACHED of the target; it used to be the target's)
    reached = {f: np.cos(np.deg2rad(MCP_REACHED * v)) for f, v in flex_deg.items()}
    want_deg = {"index": 6.0, "middle": 0.0, "ring": 6.0 * reached["ring"]}
    want_deg["pinkie"] = 12.0 * reached["pinkie"]
    for f, v in want_deg.items():
        assert np.rad2deg(got[f"{f}_mcp_abd"]) == pytest.approx(v, abs=1e-9)


def test_flat_pose_fans_the_pinkie_twice_as_far_as_the_index_and_holds_the_spread():
    pose = finger_pose("flat", still(SUBJECT, 8.0), np.random.default_rng(1))
    index, pinkie = pose.targets_rad["index_mcp_abd"], pose.targets_rad["pinkie_mcp_abd"]
    flat = np.deg2rad(20.0 * MCP_REACHED)  # flat: MCP target 20 deg
    assert np.rad2deg(index) == pytest.approx(8.0 * np.cos(flat))
    assert pinkie == pytest.approx(2 * index) and pose.targets_rad["middle_mcp_abd"] == 0.0
    fingers = {f"{f}_mcp_abd" for f in ("index", "middle", "ring", "pinkie")}
    assert set(pose.preshape) == fingers | {"thumb_cmc_flex"}  # the thumb's spread is held too


def test_whole_hand_modes_open_the_thumb_within_its_range_and_the_joint_limit():
    rng, (lo, hi) = np.random.default_rng(3), THUMB_SPREAD_DEG
    limit = JOINT_LIMITS_DEG["thumb_cmc_flex"][0]
    for mode in ("grasp", "hook", "flat", "palm"):
        radial = [-np.rad2deg(thumb_spread(mode, rng)["thumb_cmc_flex"]) for _ in range(200)]
        assert lo <= min(radial) and max(radial) <= min(hi, -limit)
    assert thumb_spread("curled", rng) == {} and thumb_spread("fingertips", rng) == {}
    pose = finger_pose("fingertips", still(SUBJECT, 8.0), rng)
    assert "thumb_cmc_flex" not in pose.preshape


def test_trial_spread_stays_inside_the_joint_limits_and_varies_with_noise():
    noisy = dataclasses.replace(SUBJECT, pose_noise_deg=8.0, finger_spread_deg=9.5)
    rng = np.random.default_rng(2)
    pinkie = [
        np.rad2deg(finger_pose("palm", noisy, rng).targets_rad["pinkie_mcp_abd"])
        for _ in range(200)
    ]
    assert max(pinkie) <= 20.0 and min(pinkie) >= 0.0  # the pinkie's abduction limit
    assert np.std(pinkie) > 1.0
    wide = dataclasses.replace(noisy, finger_spread_deg=16.0)  # twice 16 deg: held at the limit
    assert np.rad2deg(finger_pose("palm", wide, rng).targets_rad["pinkie_mcp_abd"]) <= 20.0


def test_subjects_draw_their_habit_from_the_documented_range():
    spreads = [s.finger_spread_deg for s in sample_subjects(400, np.random.default_rng(0))]
    lo, hi = FINGER_SPREAD_RANGE_DEG
    assert lo <= min(spreads) and max(spreads) <= hi
    assert np.mean(spreads) == pytest.approx((lo + hi) / 2, abs=0.4)  # uniform: se 0.12 deg
    with pytest.raises(ConfigError, match="finger_spread_deg"):
        dataclasses.replace(SUBJECT, finger_spread_deg=25.0)  # beyond the MCP abduction limit


def test_plan_refuses_a_preshape_joint_without_a_target():
    with pytest.raises(ConfigError, match="preshape"):
        PressPlan(joint_targets={"a": 0.1}, preshape=("a", "b"))


def joint_deg(scene: press.PressScene, subject: Subject, joint: str) -> np.ndarray:
    """(4,) angle (degrees) of finger joint ``joint`` (e.g. "mcp_abd") of index, middle, ring,
    pinkie of ``subject``'s hand in ``scene``'s current state."""
    m, d = scene.model, scene.data
    act = [scene.joint_act[joint_name(subject, f"{f}_{joint}")] for f in FINGERS]
    return np.rad2deg(d.qpos[m.jnt_qposadr[m.actuator_trnid[act, 0]]])


def test_the_spread_is_set_in_the_air_and_widens_the_pressed_fan():
    """At the end of the approach (the palm about to land) the abduction joints sit on their
    targets, while the flexion joints have not started to close. At the end of the hold, shear
    and friction bend the fingers (the abduction servo is weak), but the angle between index and
    pinkie is wider for a subject who spreads 8 degrees than for one who spreads none."""
    ctx = EpisodeContext()
    assert ctx.cfg.skip_release  # run_episode ends at the end of the hold
    spread = still(SUBJECT, 8.0)
    contactor = hand_contactor(spread)
    plan = plan_hand_interaction("push_away", "front", spread, ctx.part, np.random.default_rng(5))
    scene = ctx.scene(contactor)
    press.reset(scene, plan, *site_pose(ctx, plan, np.random.default_rng(0))[1:])
    ticks = int(plan.durations_s[0] / CONTROL_DT_S)
    sched = press.schedule(scene, plan, np.arange(ticks) * CONTROL_DT_S)
    n_ctrl = round(CONTROL_DT_S / scene.model.opt.timestep)
    for i in range(ticks):
        press.apply_tick(scene, sched, i)
        mujoco.mj_step(scene.model, scene.data, nstep=n_ctrl)
    want = [np.rad2deg(plan.joint_targets[joint_name(spread, f"{f}_mcp_abd")]) for f in FINGERS]
    np.testing.assert_allclose(joint_deg(scene, spread, "mcp_abd"), want, atol=1.0)
    assert np.abs(joint_deg(scene, spread, "mcp_flex")).max() < 1.0  # closes after landing

    fans = {}
    for habit in (0.0, 8.0):
        subject = still(SUBJECT, habit)
        contactor = hand_contactor(subject)
        fan = []
        for seed in range(3):
            rng = np.random.default_rng(seed)
            plan = plan_hand_interaction("push_away", "front", subject, ctx.part, rng)
            last = run_episode(ctx, contactor, plan, np.random.default_rng(seed)).frames[-1]
            assert (last.geom >= 0).sum() >= 5
            index, _, _, pinkie = joint_deg(ctx.scene(contactor), subject, "mcp_abd")
            fan.append(index + pinkie)  # the angle between index and pinkie, degrees
        fans[habit] = np.mean(fan)
    assert fans[8.0] > fans[0.0] + 3.0
