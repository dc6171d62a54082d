"""The episode runner: press a contactor on a part, read the skin at 10 Hz, keep the best frame.

`EpisodeContext` (one per worker) holds the part, its `TactileMap`, the skin instance and a cache
of compiled press scenes (one per contactor key: compiling costs tens of ms, an episode a few
hundred steps). `run_episode` simulates one `PressPlan` (the site from `sim.contactors.placement`:
the plan's lattice point mapped onto the link surface, or an aim drawn by the policy shared by all
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
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import mujoco
import numpy as np

from sim.contactors import placement
from sim.contactors.spec import ContactorSpec, PressPlan
from sim.episode import press
from sim.episode.frames import (
    Frame,
    Frames,
    label_taxels,
    read_frame,
    sensed_pressure,
    tactile_images,
)
from sim.episode.mjlog import mujoco_warnings_logged
from sim.episode.scene import link_mesh_file, skin_mesh_file
from sim.skin import DEFAULT_PART, MAP_STEP_MM
from sim.skin.model import SkinConfig, SkinInstance
from sim.skin.parts import Part, get_part
from tactile.dataset.schema import MAX_CONTACTS
from tactile.errors import ConfigError
from tactile.images.labels import label_image
from tactile.images.tactile_map import TactileMap

REASONS = ("warning", "nan", "too_deep", "no_contact", "few_taxels", "no_room")
FRAME_DT_S = 0.1  # s: the skin is sampled at 10 Hz (Albini & Cannata 2020)
CONTROL_DT_S = 0.01  # s: the schedule's targets are updated at 100 Hz
SENSOR_BIT = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)


@dataclass(frozen=True)
class EpisodeConfig:
    """Runner settings (SI units)."""

    part: str = DEFAULT_PART  # `sim.skin.parts.get_part` name
    map_step_mm: float = MAP_STEP_MM  # skin under a pixel of the tactile images, mm
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


class SampleFailed(ConfigError):
    """A sample none of whose ``max_attempts`` episodes could be kept: these settings cannot
    make it (`experiments.fidelity` records it as its setting's failure)."""


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
        self.tmap = TactileMap.build(self.part.layout, step_mm=self.cfg.map_step_mm)
        rng = np.random.default_rng(np.random.SeedSequence(self.cfg.skin_seed, spawn_key=(2**31,)))
        self.skin = SkinInstance.create(
            self.part.layout.positions_m, self.cfg.skin, rng, self.part.sensor_faces
        )
        self.along = placement.link_axis(self.part)
        # link and sensor meshes as files: compiled once, then from MuJoCo's mesh cache
        self.mesh_files = link_mesh_file(self.part), skin_mesh_file(self.part)
        self._cache: OrderedDict[str, press.PressScene] = OrderedDict()

    def scene(self, contactor: ContactorSpec | Sequence[ContactorSpec]) -> press.PressScene:
        """The compiled press scene of ``contactor`` (or of several pressing at once; LRU cache
        keyed by `contactor_key`)."""
        key = " + ".join(contactor_key(c) for c in as_list(contactor))
        if key in self._cache:
            self._cache.move_to_end(key)
            return self._cache[key]
        scene = press.build_press_scene(
            self.part, contactor, self.cfg.timestep_s, self.cfg.solver_iterations, *self.mesh_files
        )
        self._cache[key] = scene
        if len(self._cache) > self.cfg.cache_size:
            self._cache.popitem(last=False)
        return scene


def as_list(items):
    """``items`` as a list: one contactor (or plan) becomes a list of one."""
    return list(items) if isinstance(items, list | tuple) else [items]


def contactor_key(c: ContactorSpec) -> str:
    """Identity of a contactor's geometry: same key, same compiled model (the press mode a
    non-hand's description records is not geometry)."""
    geometry = {k: v for k, v in c.description.items() if k != "press"}
    return json.dumps([c.kind, c.name, c.subject_id, c.instance_id, geometry], sort_keys=True)


def site_pose(ctx: EpisodeContext, plan: PressPlan, rng: np.random.Generator):
    """Skin frame at the plan's site (the link surface under it), or at a drawn aim taxel.

    Without ``plan.site_uv`` the taxel comes from `sim.contactors.placement.draw_aim_taxel` (the
    policy shared by all contactors). Returns (taxel index nearest the site, pos (3,) m, quat (4,)
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
    contactor: ContactorSpec | Sequence[ContactorSpec],
    plan: PressPlan | Sequence[PressPlan],
    rng: np.random.Generator,
    keep_release: bool = False,
) -> Frames:
    """Simulate ``plan`` (one per contactor when several press at once) and read the skin every
    `FRAME_DT_S`; EpisodeFailure when unstable.

    Frames up to the end of the (latest) hold are always simulated and checked; with
    ``keep_release`` (or ``skip_release`` off) the release frames follow, and a failure among
    them only ends the sequence there. The selection (`Frames.best`) is among the load and hold
    frames either way.
    """
    start = start_episode(ctx, contactor, plan, rng, keep_release)
    max_pen_m = max(c.max_penetration_m for c in as_list(contactor))
    frames: list[Frame] = []
    with mujoco_warnings_logged():  # _check rejects them; no stderr line, no MUJOCO_LOG.TXT
        for k in range(start.n_frames):
            try:
                frames.append(_step_frame(ctx, start.scene, start.sched, k, max_pen_m))
            except EpisodeFailure:
                if k < start.n_hold:
                    raise
                break
    return Frames(frames, start.n_hold)


@dataclass(frozen=True)
class EpisodeStart:
    """An episode placed on its compiled scene (reset to the plan's start), ready to step:
    its per-tick schedule, the frames to simulate and the end of the hold (frames)."""

    scene: press.PressScene
    sched: press.Schedule
    n_frames: int
    n_hold: int


def start_episode(
    ctx: EpisodeContext,
    contactor: ContactorSpec | Sequence[ContactorSpec],
    plan: PressPlan | Sequence[PressPlan],
    rng: np.random.Generator,
    keep_release: bool = False,
) -> EpisodeStart:
    """Draw the site of every plan from ``rng`` (in order), reset the contactors' scene there
    and schedule the ticks (shared by `run_episode` and the batched backend,
    `sim.warp.backend`)."""
    scene, plans = ctx.scene(contactor), as_list(plan)
    poses = [site_pose(ctx, p, rng)[1:] for p in plans]
    if len(plans) == 1:
        press.reset(scene, plans[0], *poses[0])
    else:
        press.reset(scene, plans, [pos for pos, _ in poses], [quat for _, quat in poses])
    n_hold = max(_n_frames(sum(p.durations_s[:3])) for p in plans)
    release = keep_release or not ctx.cfg.skip_release
    n_frames = max(_n_frames(p.total_s) for p in plans) if release else n_hold
    per_frame = round(FRAME_DT_S / CONTROL_DT_S)
    sched = press.schedule(scene, plans, np.arange(n_frames * per_frame) * CONTROL_DT_S)
    return EpisodeStart(scene, sched, n_frames, n_hold)


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


#: ``make(rng) -> (contactor, plan)``, or (contactors, plans) for several pressing at once
Maker = Callable[[np.random.Generator], tuple[ContactorSpec | list, PressPlan | list]]


@dataclass(frozen=True)
class Attempt:
    """The kept attempt of a sample: what was pressed, its frames and its episode seed."""

    contactor: ContactorSpec | list[ContactorSpec]
    plan: PressPlan | list[PressPlan]
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
        try:
            contactor, plan = make(rng)  # a maker of several contacts may fail ("no_room")
            frames = run_episode(ctx, contactor, plan, rng, keep_release=keep_release)
            check_contact(ctx, frames)
        except EpisodeFailure as failure:
            rejects[failure.reason] += 1
            continue
        return Attempt(contactor, plan, frames, ep_seed, rejects)
    raise attempts_exhausted(index, seed, ctx, rejects)


def check_contact(ctx: EpisodeContext, frames: Frames) -> None:
    """EpisodeFailure "no_contact" / "few_taxels" unless the selected frame presses at least
    ``ctx.cfg.min_active_taxels`` taxels."""
    if frames.best_active == 0:
        raise EpisodeFailure("no_contact", "no active taxel in any frame")
    if frames.best_active < ctx.cfg.min_active_taxels:
        raise EpisodeFailure(
            "few_taxels",
            f"{frames.best_active} active taxels < min_active_taxels = {ctx.cfg.min_active_taxels}",
        )


def attempts_exhausted(
    index: int, seed: int, ctx: EpisodeContext, rejects: Counter
) -> SampleFailed:
    """The error of sample ``index`` whose ``max_attempts`` attempts all failed (by reason)."""
    cfg = ctx.cfg
    fixes = {  # the commonest reason's setting, in the configuration's words
        "few_taxels": f"lower episode.min_active_taxels (now {cfg.min_active_taxels})",
        "no_contact": f"lower episode.active_pa (now {cfg.active_pa:g} Pa; a taxel counts above "
        "it) or check episode.skin (a stiffer or less sensitive skin reads less)",
        "too_deep": "stiffen the skin (episode.skin.stiffness_pa_per_m): contactors sank deeper "
        "than their tissue allows",
        "nan": "lower episode.timestep_s or raise episode.solver_iterations (the simulation "
        "diverged)",
    }
    reason = max(rejects, key=rejects.get) if rejects else "no_contact"
    fix = f"{fixes.get(reason, fixes['nan'])}, or raise episode.max_attempts"
    return SampleFailed(
        f"sample {index} (seed {seed}) failed {ctx.cfg.max_attempts} attempts: {dict(rejects)}. "
        f"Fix: {fix}"
    )


def run_sample(
    index: int,
    seed: int,
    ctx: EpisodeContext,
    make: Maker,
    keep_sequence: bool = False,
    several: bool = False,
) -> tuple[dict, Counter]:
    """Sample ``index`` of a dataset seeded ``seed``: (sample dict, reject counts by reason),
    from the attempt `select_attempt` keeps (``several``: the dataset holds samples of several
    contacts, so every sample carries their fields)."""
    a = select_attempt(index, seed, ctx, make, keep_release=keep_sequence)
    sample = make_sample(ctx, a.contactor, a.plan, a.frames, a.ep_seed, keep_sequence, several)
    return sample, a.rejects


def reading(ctx: EpisodeContext, frame: Frame, ep_seed: int) -> np.ndarray:
    """Noisy 16-bit reading (N,) uint16 of ``frame`` (pressure scaled to its sensed force)."""
    rng = frame_rng(ep_seed, frame)
    return ctx.skin.frame(frame.depth_m, rng, frame.time_s, frame.sensed_force_n).reading


def make_sample(
    ctx: EpisodeContext,
    contactor: ContactorSpec | Sequence[ContactorSpec],
    plan: PressPlan | Sequence[PressPlan],
    frames: Frames,
    ep_seed: int,
    keep_sequence: bool,
    several: bool = False,
) -> dict:
    """The dataset sample dict (`tactile.dataset.schema`) of the best frame of ``frames``.

    With several contactors the sample's action, operator position and person are the first
    hand's, its instance the first non-hand's; ``several`` adds the fields of every contact
    (count, people, instances, the contact per pixel) and writes the contactors as a JSON list.
    """
    contactors, plans = as_list(contactor), as_list(plan)
    best = frames.best
    frames_used = frames.frames if keep_sequence else [best]
    seq = [reading(ctx, f, ep_seed) for f in frames_used]
    raw = seq[frames.best_index] if keep_sequence else seq[0]
    sensed = sensed_pressure(ctx.skin, raw, best.time_s)
    label, who = label_taxels(ctx.skin, best, ctx.cfg.active_pa, len(contactors))
    image, classes = tactile_images(ctx.tmap, sensed, label)
    kinds = [c.kind for c in contactors]
    lead = kinds.index("hand") if "hand" in kinds else 0
    other = next((c for c in contactors if c.kind != "hand"), contactors[0])
    described = [{"kind": c.kind, "name": c.name, **c.description} for c in contactors]
    sample = {
        "raw": raw,
        "pressure_pa": best.pressure_pa.astype(np.float32),
        "taxel_label": label.astype(np.uint8),
        "taxel_contactor": who.astype(np.int16),
        "image": image,
        "label_image": classes,
        "is_hand": np.uint8("hand" in kinds),
        "action": np.int8(plans[lead].action),
        "operator_position": np.int8(plans[lead].operator_position),
        "subject_id": np.int32(contactors[lead].subject_id),
        "instance_id": np.int32(other.instance_id),
        "contactor": json.dumps(described if several else described[0], sort_keys=True),
        "episode_seed": np.uint64(ep_seed),
        "force_n": np.float32(best.force_n),
        "time_s": np.float32(best.time_s),
    }
    if several:
        sample |= contact_fields(ctx, contactors, sensed, who, image)
    if keep_sequence:
        sample["seq_raw"] = np.stack(seq)
        sample["seq_length"] = np.int16(len(seq))
        sample["seq_phase_s"] = np.cumsum(plans[lead].durations_s).astype(np.float32)
    return sample


def contact_fields(ctx: EpisodeContext, contactors, sensed_pa, who, image) -> dict:
    """The fields of every contact: their count, people and instances (-1 padded to
    `MAX_CONTACTS`), and the contact of each pixel (0 none, k + 1 contact k), made like the
    label image (`tactile.images.labels.label_image` over contacts instead of hand parts)."""
    pad = [-1] * (MAX_CONTACTS - len(contactors))
    return {
        "n_contacts": np.uint8(len(contactors)),
        "contact_subject": np.array([c.subject_id for c in contactors] + pad, np.int32),
        "contact_instance": np.array([c.instance_id for c in contactors] + pad, np.int32),
        "instance_image": label_image(ctx.tmap, sensed_pa, who + 1, image=image),
    }
