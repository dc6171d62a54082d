"""The episode runner against closed forms: a sphere pressed on the flat plate, sensors only at
frame times, 10 Hz sequences, retries with derived seeds, determinism, the sample schema."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from sim.contactors import placement
from sim.contactors.spec import PressPlan, sphere_contactor
from sim.episode import press
from sim.episode.runner import (
    FRAME_DT_S,
    EpisodeConfig,
    EpisodeContext,
    episode_rng,
    run_episode,
    run_sample,
    site_pose,
)
from sim.skin.model import SkinConfig
from sim.skin.parts import get_part
from tactile.dataset.schema import Dims, validate_sample
from tactile.errors import ConfigError

RADIUS_M = 0.015
PLAN = PressPlan(site_uv=(0.0, 0.0), force_n=5.0, durations_s=(0.2, 0.3, 0.3, 0.2))


@pytest.fixture(scope="module")
def ctx() -> EpisodeContext:
    return EpisodeContext(EpisodeConfig(part="plate"))


def sphere_maker(radius_m: float = RADIUS_M, plan: PressPlan = PLAN):
    contactor = sphere_contactor(radius_m)
    return lambda rng: (contactor, plan)


def test_sphere_activates_the_closed_form_taxels(ctx):
    contactor = sphere_contactor(RADIUS_M)
    frames = run_episode(ctx, contactor, PLAN, np.random.default_rng(0))
    scene = ctx.scene(contactor)
    best = frames.frames[-1]  # end of hold: settled
    centre = scene.data.geom_xpos[scene.model.geom("c_sphere").id]
    dist = np.linalg.norm(ctx.part.layout.positions_m - centre, axis=1)
    inside, outside = dist < RADIUS_M - 1e-4, dist > RADIUS_M + 1e-4
    pressed = best.depth_m > 0
    assert inside.sum() >= 5
    assert pressed[inside].all() and not pressed[outside].any()
    assert np.allclose(best.depth_m[inside], RADIUS_M - dist[inside], atol=1e-6)
    assert best.force_n == pytest.approx(PLAN.force_n, rel=0.05)


def test_press_frame_follows_the_skin_normal(ctx):
    """The site (0, 0) mm of the plate's lattice is its top face's centre (z = 0, normal +z)."""
    k, pos, quat = site_pose(ctx, PLAN, np.random.default_rng(0))
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat)
    assert np.allclose(mat.reshape(3, 3)[:, 2], ctx.part.layout.normals[k])
    assert np.allclose(pos, [0.0, 0.0, 0.0], atol=1e-9)
    assert np.linalg.norm(ctx.part.flat_mm[k]) < 10.0  # the nearest taxel


def test_forearm_site_between_taxels_lies_on_the_link():
    """A lattice point between taxels maps onto the forearm's surface (distance to the mesh from
    trimesh's exact closest point) with the normal of its nearest taxel's neighbourhood."""
    import trimesh

    part = get_part("forearm")
    rng = np.random.default_rng(5)
    for k in rng.integers(part.n_taxels, size=5):
        uv = part.flat_mm[k] + rng.uniform(-4.0, 4.0, 2)
        pos, normal = placement.surface_point(part, uv)
        _, dist, _ = trimesh.proximity.closest_point_naive(part.link, pos[None])
        assert dist[0] < 5e-4
        assert normal @ part.layout.normals[k] > np.cos(np.deg2rad(20))
        assert np.linalg.norm(pos - part.layout.positions_m[k]) < 0.008


def test_sensors_off_between_frames_give_the_same_readings(ctx):
    """The runner disables sensors while stepping; a run with sensors always on must read the
    same depth at the frame times (sensors do not feed back into the dynamics)."""
    contactor = sphere_contactor(RADIUS_M)
    frames = run_episode(ctx, contactor, PLAN, np.random.default_rng(0))
    scene = ctx.scene(contactor)
    _, pos, quat = site_pose(ctx, PLAN, np.random.default_rng(0))
    press.reset(scene, PLAN, pos, quat)
    m, d = scene.model, scene.data
    n_ctrl = round(0.01 / m.opt.timestep)
    for j in range(round(frames.frames[-1].time_s / 0.01)):
        press.apply_controls(scene, PLAN, j * 0.01)
        mujoco.mj_step(m, d, nstep=n_ctrl)
    mujoco.mj_forward(m, d)
    assert np.array_equal(scene.readout.depth_m(d), frames.frames[-1].depth_m)


def test_sample_matches_schema_and_sequence_is_10_hz(ctx):
    sample, rejects = run_sample(3, 11, ctx, sphere_maker(), keep_sequence=True)
    dims = Dims(ctx.part.n_taxels, *ctx.tmap.shape, seq_len=int(sample["seq_length"]))
    validate_sample(sample, dims)
    assert not rejects
    assert int(sample["seq_length"]) == round(PLAN.total_s / FRAME_DT_S)
    best = round(float(sample["time_s"]) / FRAME_DT_S) - 1
    assert np.array_equal(sample["seq_raw"][best], sample["raw"])
    assert sample["taxel_contactor"].max() == 0 and (sample["taxel_label"] == 0).all()
    # 5 N on the R 15 mm sphere: a 24 kPa peak, unsaturated, so the image's erosion (disk of
    # 2 px) trims the peak pixel (before the force-consistent pressure it saturated at 255)
    assert sample["image"].max() > 150


def test_same_seed_and_index_give_identical_samples(ctx):
    a, _ = run_sample(5, 3, ctx, sphere_maker())
    b, _ = run_sample(5, 3, EpisodeContext(EpisodeConfig(part="plate")), sphere_maker())
    c, _ = run_sample(6, 3, ctx, sphere_maker())
    for key in ("raw", "pressure_pa", "image", "taxel_contactor"):
        assert np.array_equal(a[key], b[key]), key
    assert a["episode_seed"] == b["episode_seed"] != c["episode_seed"]
    assert not np.array_equal(a["raw"], c["raw"])


def test_solver_iteration_cap_reaches_the_model_and_4_do_not_bind(ctx):
    """docs/fidelity.md measured at most 4 solver iterations per step: a cap of 4 must give the
    default's (100) sample exactly; the cap is MuJoCo's opt.iterations of the compiled scene."""
    capped = EpisodeContext(EpisodeConfig(part="plate", solver_iterations=4))
    assert capped.scene(sphere_contactor(RADIUS_M)).model.opt.iterations == 4
    assert ctx.scene(sphere_contactor(RADIUS_M)).model.opt.iterations == 100
    a, _ = run_sample(5, 3, ctx, sphere_maker())
    b, _ = run_sample(5, 3, capped, sphere_maker())
    for key in ("raw", "pressure_pa", "image"):
        assert np.array_equal(a[key], b[key]), key


def test_failed_episode_is_counted_and_retried_with_a_new_seed(ctx):
    shallow = dataclasses.replace(sphere_contactor(RADIUS_M), max_penetration_m=1e-5)
    good = sphere_contactor(RADIUS_M)
    attempts = []

    def make(rng):
        attempts.append(rng.random())
        return (shallow if len(attempts) == 1 else good), PLAN

    sample, rejects = run_sample(2, 9, ctx, make)
    assert rejects == {"too_deep": 1}
    assert attempts[0] != attempts[1]
    assert int(sample["episode_seed"]) == episode_rng(9, 2, 1)[1] != episode_rng(9, 2, 0)[1]


def test_impossible_limit_gives_up_after_max_attempts():
    ctx = EpisodeContext(EpisodeConfig(part="plate", max_attempts=2))
    shallow = dataclasses.replace(sphere_contactor(RADIUS_M), max_penetration_m=1e-5)
    with pytest.raises(ConfigError, match="too_deep"):
        run_sample(0, 0, ctx, lambda rng: (shallow, PLAN))


def test_sphere_pressure_is_force_consistent_and_centre_peaked():
    """Force-consistent pressure on the plate: with and without the default spread Σ p A = F
    within 5 % and the peak at a taxel nearest the centre; without spread p_i = F (R - rho_i) /
    Σ (R - rho) A (the sphere's depth profile scaled to the sensed force), symmetric."""
    contactor = sphere_contactor(RADIUS_M)
    for sigma in (3e-3, 0.0):  # the closed forms below use the last (no spread)
        local = EpisodeContext(EpisodeConfig(part="plate", skin=SkinConfig(spread_sigma_m=sigma)))
        best = run_episode(local, contactor, PLAN, np.random.default_rng(0)).frames[-1]
        area = local.skin.area_m2
        assert best.sensed_force_n == pytest.approx(best.force_n, rel=1e-9)
        assert best.pressure_pa @ area == pytest.approx(PLAN.force_n, rel=0.05)
        scene = local.scene(contactor)
        centre = scene.data.geom_xpos[scene.model.geom("c_sphere").id]
        rho = np.linalg.norm(local.part.layout.positions_m - centre, axis=1)
        assert rho[np.argmax(best.pressure_pa)] == pytest.approx(rho.min(), abs=1e-9)
    twins = np.isclose(rho[:, None], rho[None, :], atol=1e-9) & (rho < RADIUS_M)[:, None]
    rows, cols = np.nonzero(twins)  # taxels at the same distance from the centre: same pressure
    np.testing.assert_allclose(best.pressure_pa[rows], best.pressure_pa[cols], rtol=1e-6)
    depth = np.maximum(RADIUS_M - rho, 0.0)
    np.testing.assert_allclose(
        best.pressure_pa,
        local.skin.spread @ (best.sensed_force_n * depth / (depth @ area)),
        rtol=1e-3,
        atol=1e-3,
    )


def test_contact_on_bare_link_reads_zero(ctx):
    """A sphere on the plate's bare margin (taxels end at 84.5 mm, the plate at 100 mm)."""
    plan = dataclasses.replace(PLAN, site_uv=(95.0, 0.0))
    best = run_episode(ctx, sphere_contactor(0.005), plan, np.random.default_rng(0)).frames[-1]
    assert best.force_n == pytest.approx(PLAN.force_n, rel=0.05)
    assert best.sensed_force_n == 0.0 and not best.depth_m.any()
    assert not best.pressure_pa.any() and best.active == 0


def test_sample_does_not_depend_on_keep_sequence():
    """Same (seed, i) with and without the sequence: the release frames are simulated after the
    selection window (load + hold), so every non-sequence field is identical."""
    from sim.contactors.subjects import sample_subjects
    from sim.generate.hands import sample_hand

    forearm = EpisodeContext()
    subjects = sample_subjects(4, np.random.default_rng(0))
    for i in (10, 11, 12):
        kept, _ = sample_hand(i, 0, forearm, subjects, keep_sequence=True)
        plain, _ = sample_hand(i, 0, forearm, subjects, keep_sequence=False)
        assert set(kept) - set(plain) == {"seq_raw", "seq_length", "seq_phase_s"}
        for key, value in plain.items():
            assert np.array_equal(np.asarray(kept[key]), np.asarray(value)), key
        assert int(kept["seq_length"]) > round(float(plain["time_s"]) / FRAME_DT_S)


def test_sequence_phases_end_where_the_frames_do():
    """A kept sequence holds one 10 Hz frame per 0.1 s up to the end of its release, the last
    of the four phase ends (increasing), unless an unstable release frame cut it short."""
    from sim.contactors.subjects import sample_subjects
    from sim.generate.hands import sample_hand

    forearm = EpisodeContext()
    subjects = sample_subjects(4, np.random.default_rng(0))
    for i in (3, 4):
        kept, _ = sample_hand(i, 0, forearm, subjects, keep_sequence=True)
        phases = kept["seq_phase_s"]
        assert phases.shape == (4,) and (np.diff(phases) > 0).all()
        assert int(kept["seq_length"]) <= int(np.floor(phases[-1] / FRAME_DT_S + 1e-6))
        assert int(kept["seq_length"]) >= int(np.floor(phases[2] / FRAME_DT_S + 1e-6))
        assert float(kept["time_s"]) <= phases[2] + 1e-6  # selected within load and hold


def test_a_standoff_holds_the_root_off_the_skin_and_a_press_sinks():
    """The root's normal target: from `APPROACH_HEIGHT_M` down to the standoff and back, never
    below it (the closing joints alone touch); without one it sinks `PRESS_DEPTH_M` below."""
    t = np.linspace(0.0, 1.0, 201)
    held = PressPlan(standoff_m=0.012, durations_s=(0.2, 0.3, 0.3, 0.2))
    z = press.root_schedule(held, t)[0][:, 2]
    assert z[0] == pytest.approx(press.APPROACH_HEIGHT_M) and z.min() == pytest.approx(0.012)
    assert np.all(z[(t >= 0.2) & (t <= 0.8)] == pytest.approx(0.012))
    sunk = press.root_schedule(dataclasses.replace(held, standoff_m=0.0), t)[0][:, 2]
    assert sunk.min() == pytest.approx(-press.PRESS_DEPTH_M)


@pytest.mark.parametrize("standoff", [-0.001, 0.03, float("nan")])
def test_a_standoff_out_of_range_is_refused(standoff):
    with pytest.raises(ConfigError, match="standoff_m"):
        PressPlan(standoff_m=standoff)
