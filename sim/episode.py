"""The episode runner: press a contactor on a part, read the skin at 10 Hz, keep the best frame.

`EpisodeContext` (one per worker) holds the part, its `TactileMap`, the skin instance and a cache
of compiled press scenes (one per contactor key: compiling costs tens of ms, an episode a few
hundred steps). `run_episode` simulates one `PressPlan` (the site from `sim.placement`: the plan's
lattice point mapped onto the link surface, or an aim drawn by the policy shared by all
contactors) and returns its frames; `run_sample`
wraps it with the stability checks and retries of docs/DESIGN.md and returns the sample dict of
the dataset schema (`tactile.dataset.schema`) plus reject counts by reason.

A sample does not depend on ``keep_sequence``: the frames up to the end of the hold are always
simulated and the selected frame is chosen among them (`Frames.n_select`); a kept sequence only
adds the release frames after them (same state, same per-frame noise), and a failure there ends
the sequence early instead of rejecting the episode (tests/sim/test_episode.py checks that every
non-sequence field is identical either way).

Sensors are computed only at frame times: `mjDSBL_SENSOR` is set while stepping and cleared for
one `mj_forward` per frame (tests/sim/test_episode.py checks that the readings equal those of a
run with sensors always on).
"""

from __future__ import annotations

import json
from collections import Counter, OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field

import mujoco
import numpy as np

from sim import placement, press
from sim.contactors import ContactorSpec, PressPlan
from sim.episode_frames import (
    Frame,
    Frames,
    label_taxels,
    read_frame,
    sensed_pressure,
    tactile_images,
)
from sim.mjlog import mujoco_warnings_logged
from sim.parts import Part, get_part
from sim.skin import SkinConfig, SkinInstance
from tactile.errors import ConfigError
from tactile.tactile_map import TactileMap

REASONS = ("warning", "nan", "too_deep", "no_contact", "few_taxels")
FRAME_DT_S = 0.1  # s: the skin is sampled at 10 Hz (Albini & Cannata 2020)
CONTROL_DT_S = 0.01  # s: the schedule's targets are updated at 100 Hz
SENSOR_BIT = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)


@dataclass(frozen=True)
class EpisodeConfig:
    """Runner settings (SI units)."""

    part: str = "forearm"  # `sim.parts.get_part` name
    timestep_s: float = 0.005  # implicitfast + soft tissue (solref 10 ms, 2 steps) stable at 5 ms
    # MuJoCo's cap on constraint-solver iterations per step (opt.iterations; Newton solver). The
    # forearm's presses take 1.1 on average and at most 4 (docs/fidelity.md), so 100 never binds.
    solver_iterations: int = 100
    skin: SkinConfig = field(default_factory=SkinConfig)
    skin_seed: int = 0  # draws of the one physical skin (gain, baseline, drift) of a dataset
    active_pa: float = 500.0  # a taxel is active above this noise-free pressure (~3 noise sd), Pa
    max_attempts: int = 8  # episodes tried per sample before giving up
    # Count: an episode whose selected frame has fewer active taxels is rejected ("few_taxels")
    # and retried, as a recording protocol that keeps only contacts of at least this size would;
    # 1 keeps every contact (docs/generate.md "Small contacts" gives the measured effect).
    min_active_taxels: int = 1
    cache_size: int = 16  # compiled press scenes kept per worker
    skip_release: bool = True  # stop after hold unless the sequence is kept (the frame is
    # selected among load and hold frames either way; release frames only shrink the contact)


class EpisodeFailure(Exception):
    """An episode went wrong; ``reason`` is one of `REASONS`."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}")
        self.reason = reason


class EpisodeContext:
    """Per-worker state: part, map, skin instance and the cache of compiled press scenes."""

    def __init__(self, cfg: EpisodeConfig | None = None, part: Part | None = None) -> None:
        self.cfg = cfg or EpisodeConfig()
        self.part = part or get_part(self.cfg.part)
        n_taxels = len(self.part.layout.positions_m)
        if self.cfg.min_active_taxels > n_taxels:
            raise ConfigError(
                f"episode.min_active_taxels = {self.cfg.min_active_taxels} is more than the "
                f"{n_taxels} taxels of part {self.cfg.part!r}; lower it"
            )
        self.tmap = TactileMap.build(self.part.layout)
        rng = np.random.default_rng(np.random.SeedSequence(self.cfg.skin_seed, spawn_key=(2**31,)))
        self.skin = SkinInstance.create(
            self.part.layout.positions_m, self.cfg.skin, rng, self.part.sensor_faces
        )
        self.along = placement.link_axis(self.part)
        self._cache: OrderedDict[str, press.PressScene] = OrderedDict()

    def scene(self, contactor: ContactorSpec) -> press.PressScene:
        """The compiled press scene of ``contactor`` (LRU cache keyed by `contactor_key`)."""
        key = contactor_key(contactor)
        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        scene = press.build_press_scene(
            self.part, contactor, self.cfg.timestep_s, self.cfg.solver_iterations
        )
        self._cache[key] = scene
        if len(self._cache) > self.cfg.cache_size:
            self._cache.popitem(last=False)
        return scene


def contactor_key(c: ContactorSpec) -> str:
    """Identity of a contactor's geometry: same key, same compiled model."""
    return json.dumps([c.kind, c.name, c.subject_id, c.instance_id, c.description], sort_keys=True)


def site_pose(ctx: EpisodeContext, plan: PressPlan, rng: np.random.Generator):
    """Skin frame at the plan's site (the link surface under it), or at a drawn aim taxel.

    Without ``plan.site_uv`` the taxel comes from `sim.placement.draw_aim_taxel` (the policy
    shared by all contactors). Returns (taxel index nearest the site, pos (3,) m, quat (4,)
    w x y z): z the outward normal, x the link axis projected on the tangent plane.
    """
    if plan.site_uv is None:
        k = placement.draw_aim_taxel(ctx.part, rng)
        pos, z = ctx.part.layout.positions_m[k].copy(), ctx.part.layout.normals[k]
    else:
        uv = np.asarray(plan.site_uv, float)
        k = int(np.argmin(np.sum((ctx.part.flat_mm - uv) ** 2, axis=1)))
        pos, z = placement.surface_point(ctx.part, uv)
    x = ctx.along - np.dot(ctx.along, z) * z
    x /= np.linalg.norm(x)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.column_stack([x, np.cross(z, x), z]).ravel())
    return k, pos, quat


def _check(scene: press.PressScene, depth_m: np.ndarray, max_pen_m: float) -> None:
    d = scene.data
    if not (np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()):
        raise EpisodeFailure("nan", "non-finite state")
    counts = d.warning.number  # (mjNWARNING,) one vector read, not a Python loop over structs
    if counts.any():
        warned = [mujoco.mjtWarning(i).name for i in np.flatnonzero(counts)]
        raise EpisodeFailure("warning", ", ".join(warned))
    if depth_m.max() > max_pen_m:
        raise EpisodeFailure("too_deep", f"{depth_m.max() * 1e3:.2f} mm > {max_pen_m * 1e3:.2f}")


def run_episode(
    ctx: EpisodeContext,
    contactor: ContactorSpec,
    plan: PressPlan,
    rng: np.random.Generator,
    keep_release: bool = False,
) -> Frames:
    """Simulate ``plan`` and read the skin every `FRAME_DT_S`; EpisodeFailure when unstable.

    Frames up to the end of the hold are always simulated and checked; with ``keep_release`` (or
    ``skip_release`` off) the release frames follow, and a failure among them only ends the
    sequence there. The selection (`Frames.best`) is among the load and hold frames either way.
    """
    scene = ctx.scene(contactor)
    _, pos, quat = site_pose(ctx, plan, rng)
    press.reset(scene, plan, pos, quat)
    n_hold = _n_frames(sum(plan.durations_s[:3]))
    release = keep_release or not ctx.cfg.skip_release
    n_frames = _n_frames(plan.total_s) if release else n_hold
    per_frame = round(FRAME_DT_S / CONTROL_DT_S)
    sched = press.schedule(scene, plan, np.arange(n_frames * per_frame) * CONTROL_DT_S)
    frames: list[Frame] = []
    with mujoco_warnings_logged():  # _check rejects them; no stderr line, no MUJOCO_LOG.TXT
        for k in range(n_frames):
            try:
                frames.append(_step_frame(ctx, scene, sched, k, contactor.max_penetration_m))
            except EpisodeFailure:
                if k < n_hold:
                    raise
                break
    return Frames(frames, n_hold)


def _n_frames(duration_s: float) -> int:
    return int(np.floor(duration_s / FRAME_DT_S + 1e-9))


def _step_frame(
    ctx: EpisodeContext, scene: press.PressScene, sched: press.Schedule, k: int, max_pen_m: float
) -> Frame:
    """Simulate frame ``k`` (its control ticks), read and check it."""
    m, d = scene.model, scene.data
    n_ctrl = max(1, round(CONTROL_DT_S / m.opt.timestep))
    per_frame = round(FRAME_DT_S / CONTROL_DT_S)
    m.opt.disableflags |= SENSOR_BIT
    for j in range(per_frame):
        press.apply_tick(scene, sched, k * per_frame + j)
        mujoco.mj_step(m, d, nstep=n_ctrl)
    m.opt.disableflags &= ~SENSOR_BIT
    mujoco.mj_forward(m, d)
    frame = read_frame(scene, ctx.skin, ctx.cfg.active_pa, (k + 1) * FRAME_DT_S)
    _check(scene, frame.depth_m, max_pen_m)
    return frame


def episode_rng(seed: int, index: int, attempt: int) -> tuple[np.random.Generator, int]:
    """Generator and uint64 seed of attempt ``attempt`` of sample ``index`` (DESIGN.md)."""
    seq = np.random.SeedSequence(seed, spawn_key=(index, attempt))
    return np.random.default_rng(seq), int(seq.generate_state(1, np.uint64)[0])


def frame_rng(ep_seed: int, frame: Frame) -> np.random.Generator:
    """Read-noise generator of one frame: depends only on the episode seed and the frame time."""
    return np.random.default_rng([ep_seed, round(frame.time_s / FRAME_DT_S)])


Maker = Callable[[np.random.Generator], tuple[ContactorSpec, PressPlan]]


@dataclass(frozen=True)
class Attempt:
    """The kept attempt of a sample: what was pressed, its frames and its episode seed."""

    contactor: ContactorSpec
    plan: PressPlan
    frames: Frames
    ep_seed: int  # uint64 episode seed (`episode_rng`): the read noise of its frames
    rejects: Counter  # failed attempts before it, by reason (`REASONS`)


def select_attempt(
    index: int, seed: int, ctx: EpisodeContext, make: Maker, keep_release: bool = False
) -> Attempt:
    """The first attempt of sample ``index`` (dataset seed ``seed``) that passes the checks.

    ``make(rng)`` draws the contactor and plan of an attempt. An attempt fails when its episode
    is unstable (`_check`), presses no taxel ("no_contact") or fewer than
    ``ctx.cfg.min_active_taxels`` at its selected frame ("few_taxels"); it is then retried with
    `episode_rng(seed, index, attempt + 1)`. ConfigError after ``max_attempts`` failures.
    """
    rejects: Counter = Counter()
    for attempt in range(ctx.cfg.max_attempts):
        rng, ep_seed = episode_rng(seed, index, attempt)
        contactor, plan = make(rng)
        try:
            frames = run_episode(ctx, contactor, plan, rng, keep_release=keep_release)
            if frames.best_active == 0:
                raise EpisodeFailure("no_contact", "no active taxel in any frame")
            if frames.best_active < ctx.cfg.min_active_taxels:
                raise EpisodeFailure(
                    "few_taxels",
                    f"{frames.best_active} active taxels < "
                    f"min_active_taxels = {ctx.cfg.min_active_taxels}",
                )
        except EpisodeFailure as failure:
            rejects[failure.reason] += 1
            continue
        return Attempt(contactor, plan, frames, ep_seed, rejects)
    fix = (
        "lower episode.min_active_taxels or raise episode.max_attempts"
        if rejects["few_taxels"]
        else "check the contactor's force and max_penetration_m, or raise max_attempts"
    )
    raise ConfigError(
        f"sample {index} (seed {seed}) failed {ctx.cfg.max_attempts} attempts: {dict(rejects)}. "
        f"Fix: {fix}"
    )


def run_sample(
    index: int, seed: int, ctx: EpisodeContext, make: Maker, keep_sequence: bool = False
) -> tuple[dict, Counter]:
    """Sample ``index`` of a dataset seeded ``seed``: (sample dict, reject counts by reason),
    from the attempt `select_attempt` keeps."""
    a = select_attempt(index, seed, ctx, make, keep_release=keep_sequence)
    return make_sample(ctx, a.contactor, a.plan, a.frames, a.ep_seed, keep_sequence), a.rejects


def reading(ctx: EpisodeContext, frame: Frame, ep_seed: int) -> np.ndarray:
    """Noisy 16-bit reading (N,) uint16 of ``frame`` (pressure scaled to its sensed force)."""
    rng = frame_rng(ep_seed, frame)
    return ctx.skin.frame(frame.depth_m, rng, frame.time_s, frame.sensed_force_n).reading


def make_sample(
    ctx: EpisodeContext,
    contactor: ContactorSpec,
    plan: PressPlan,
    frames: Frames,
    ep_seed: int,
    keep_sequence: bool,
) -> dict:
    """The dataset sample dict (`tactile.dataset.schema`) of the best frame of ``frames``."""
    best = frames.best
    frames_used = frames.frames if keep_sequence else [best]
    seq = [reading(ctx, f, ep_seed) for f in frames_used]
    raw = seq[frames.best_index] if keep_sequence else seq[0]
    sensed = sensed_pressure(ctx.skin, raw, best.time_s)
    label, who = label_taxels(ctx.skin, best, ctx.cfg.active_pa)
    image, label_image = tactile_images(ctx.tmap, sensed, label)
    sample = {
        "raw": raw,
        "pressure_pa": best.pressure_pa.astype(np.float32),
        "taxel_label": label.astype(np.uint8),
        "taxel_contactor": who.astype(np.int16),
        "image": image,
        "label_image": label_image,
        "is_hand": np.uint8(contactor.kind == "hand"),
        "action": np.int8(plan.action),
        "operator_position": np.int8(plan.operator_position),
        "subject_id": np.int32(contactor.subject_id),
        "instance_id": np.int32(contactor.instance_id),
        "contactor": json.dumps(
            {"kind": contactor.kind, "name": contactor.name, **contactor.description},
            sort_keys=True,
        ),
        "episode_seed": np.uint64(ep_seed),
        "force_n": np.float32(best.force_n),
        "time_s": np.float32(best.time_s),
    }
    if keep_sequence:
        sample["seq_raw"] = np.stack(seq)
        sample["seq_length"] = np.int16(len(seq))
    return sample
