"""Per-worker sampling: the state a worker builds once, and `make_chunk(k)` computed from it.

A worker (a pool process, a Ray actor, or the parent itself with one worker) calls
`init_worker(cfg)` once: it builds the part, the `EpisodeContext` (tactile map, skin instance,
compiled-scene cache) and the subject pool. `make_chunk(k)` then computes chunk ``k``: sample
``i`` is a hand when `is_hand_index(i, hand_fraction)`, drawn by `sim.generate.hands.hand_maker`
from the pool, else a non-hand from `sim.contactors.nonhand.sample_nonhand`;
`sim.episode.runner.run_sample` runs it with seeds from ``(seed, i, attempt)`` only, so the bytes
never depend on which worker ran what.
"""

from __future__ import annotations

import ctypes
import os
import signal
from collections import Counter
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from sim.contactors.hand import HandConfig
from sim.contactors.nonhand import sample_nonhand
from sim.contactors.spec import ContactorSpec, PressPlan
from sim.contactors.subjects import Subject, sample_subjects
from sim.episode.runner import EpisodeContext, Maker, run_sample
from sim.generate.config import GenerateConfig, is_mesh_path
from sim.generate.hands import hand_maker
from sim.generate.mix import SecondContact, is_mix_index
from sim.skin.parts import W0_REGION, W0_TILING, Part, custom_part, get_part
from tactile.errors import ConfigError

# Spawn key of the subject pool: a 1-tuple above every sample index, so it never meets the
# per-sample keys (i, attempt) nor the skin's (2**31,).
SUBJECT_SPAWN_KEY = (2**31 + 1,)
Sample = dict[str, np.ndarray]


@dataclass
class WorkerState:
    """What one worker builds once: the config, episode context, subjects and the two makers."""

    cfg: GenerateConfig
    ctx: EpisodeContext
    subjects: list[Subject]
    hand: Maker
    nonhand: Maker
    mix_hand: Maker | None = None  # a hand and a second contact (`sim.generate.mix`), when mixing
    mix_nonhand: Maker | None = None


_STATE: WorkerState | None = None


def is_hand_index(i: int, hand_fraction: float) -> bool:
    """Whether sample ``i`` is a hand contact: a Bresenham sequence, exact over every prefix.

    Over samples 0..n-1 exactly ``floor(n · hand_fraction)`` are hands, evenly interleaved, and
    the answer for ``i`` does not depend on ``n`` (so a dataset can be extended or sharded).
    """
    return int(np.floor((i + 1) * hand_fraction)) - int(np.floor(i * hand_fraction)) == 1


def build_part(cfg: GenerateConfig) -> Part:
    """The configured part: a built-in one, or a link mesh covered like Baxter W0."""
    if not is_mesh_path(cfg.part):
        return get_part(cfg.part)
    return custom_part(cfg.part, W0_REGION, W0_TILING, Path(cfg.part).stem)


def subject_pool(cfg: GenerateConfig) -> list[Subject]:
    """The dataset's ``n_subjects`` people (ids s0000..), from the dataset seed only."""
    seq = np.random.SeedSequence(cfg.seed, spawn_key=SUBJECT_SPAWN_KEY)
    people = sample_subjects(cfg.n_subjects, np.random.default_rng(seq))
    if cfg.hand_detail == HandConfig.detail:
        return people
    return [replace(s, hand=replace(s.hand, detail=cfg.hand_detail)) for s in people]


def scaled(make: Maker, factor: float) -> Maker:
    """``make`` with every plan's phase durations multiplied by ``factor`` (1: unchanged)."""
    if factor == 1.0:
        return make

    def scale(plan: PressPlan) -> PressPlan:
        return replace(plan, durations_s=tuple(d * factor for d in plan.durations_s))

    def make_scaled(rng: np.random.Generator) -> tuple[ContactorSpec | list, PressPlan | list]:
        spec, plan = make(rng)
        return spec, [scale(p) for p in plan] if isinstance(plan, list) else scale(plan)

    return make_scaled


def build_state(cfg: GenerateConfig, ctx: EpisodeContext | None = None) -> WorkerState:
    """A worker's state for ``cfg`` (``ctx`` reused when given, e.g. the parent's)."""
    ctx = ctx or EpisodeContext(cfg.episode, part=build_part(cfg))
    subjects = subject_pool(cfg)
    k, factor = cfg.instances_per_kind, cfg.duration_scale
    hand, nonhand = hand_maker(subjects, ctx), lambda rng: sample_nonhand(rng, k)
    state = WorkerState(cfg, ctx, subjects, scaled(hand, factor), scaled(nonhand, factor))
    if cfg.mix.fraction > 0:
        m = cfg.mix
        weights = (m.same_person, m.two_people, m.hand_object, m.hand_body)
        second = SecondContact(ctx, subjects, k, weights, m.min_gap_mm, cfg.seed)
        state.mix_hand = scaled(second.maker(hand), factor)
        state.mix_nonhand = scaled(second.maker(nonhand), factor)
    return state


def init_worker(cfg: GenerateConfig, ctx: EpisodeContext | None = None) -> None:
    """Build this process's state once (kept when a forked worker inherits the same config)."""
    global _STATE
    if _STATE is None or _STATE.cfg != cfg:
        _STATE = build_state(cfg, ctx)


def current_state() -> WorkerState:
    """This process's worker state (RuntimeError before `init_worker`)."""
    if _STATE is None:
        raise RuntimeError("worker state used before init_worker(cfg)")
    return _STATE


def pad_sequence(sample: Sample, frames: int) -> Sample:
    """``seq_raw`` (F, N) zero-padded to (frames, N); ConfigError when F > frames."""
    seq = sample["seq_raw"]
    if len(seq) > frames:
        raise ConfigError(
            f"an episode has {len(seq)} frames > sequence_frames = {frames}; raise sequence_frames"
        )
    out = np.zeros((frames, seq.shape[1]), dtype=seq.dtype)
    out[: len(seq)] = seq
    return sample | {"seq_raw": out}


def maker_at(i: int, state: WorkerState) -> Maker:
    """The maker of sample ``i``: hands at `is_hand_index`, non-hands elsewhere; with a second
    contact at `sim.generate.mix.is_mix_index` when the dataset mixes."""
    hand = is_hand_index(i, state.cfg.hand_fraction)
    if state.mix_hand is not None and is_mix_index(i, state.cfg.seed, state.cfg.mix.fraction):
        return state.mix_hand if hand else state.mix_nonhand
    return state.hand if hand else state.nonhand


def sample_at(i: int, state: WorkerState) -> tuple[Sample, Counter]:
    """Sample ``i`` of the dataset and its reject counts by reason."""
    cfg = state.cfg
    several = cfg.mix.fraction > 0
    make = maker_at(i, state)
    sample, rejects = run_sample(i, cfg.seed, state.ctx, make, cfg.keep_sequences, several)
    if cfg.keep_sequences:
        sample = pad_sequence(sample, cfg.sequence_frames)
    return sample, rejects


def make_chunk(k: int) -> tuple[int, list[Sample], dict[str, int]]:
    """Chunk ``k``: (k, its samples in index order, reject counts by reason)."""
    if _STATE is None:
        raise RuntimeError("make_chunk called before init_worker(cfg)")
    cfg = _STATE.cfg
    start = k * cfg.chunk_size
    stop = min(start + cfg.chunk_size, cfg.n)
    samples, rejects = [], Counter()
    for i in range(start, stop):
        sample, why = sample_at(i, _STATE)
        samples.append(sample)
        rejects.update(why)
    release_free_memory()
    return k, samples, dict(rejects)


def release_free_memory() -> None:
    """Return freed heap pages to the OS (glibc ``malloc_trim``; no-op elsewhere).

    Every episode compiles MuJoCo scenes (contactor specs, models); the freed blocks stay in
    glibc's arenas, fragmented, and without trimming a worker's memory grows by about 50 KB per
    sample. Trimming after each chunk keeps it flat.
    """
    try:
        ctypes.CDLL("libc.so.6").malloc_trim(0)
    except (OSError, AttributeError):
        pass


def pool_worker_init(cfg: GenerateConfig, parent_pid: int) -> None:
    """Pool worker start: die with the parent (a SIGKILLed parent leaves no orphans blocked on
    the task queue; Linux prctl PR_SET_PDEATHSIG), then build the worker state."""
    try:
        pr_set_pdeathsig = 1
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(pr_set_pdeathsig, int(signal.SIGKILL))
    except (OSError, AttributeError):  # not Linux: orphans end when the queue breaks
        pass
    if os.getppid() != parent_pid:  # the parent died before prctl took effect
        os._exit(1)
    init_worker(cfg)


class RayWorker:
    """A Ray actor holding one worker state (see `sim.generate.sampler`)."""

    def __init__(self, cfg: GenerateConfig) -> None:
        init_worker(cfg)

    def make_chunk(self, k: int) -> tuple[int, list[Sample], dict[str, int]]:
        return make_chunk(k)
