"""Per-worker sampling: the state a worker builds once, and `make_chunk(k)` computed from it.

A worker (a pool process, a Ray actor, or the parent itself with one worker) calls
`init_worker(cfg)` once: it builds the part, the `EpisodeContext` (tactile map, skin instance,
compiled-scene cache) and the subject pool. `make_chunk(k)` then computes chunk ``k``: sample
``i`` is a hand when `is_hand_index(i, hand_fraction)`, drawn by `sim.generate_hands.hand_maker`
from the pool, else a non-hand from `sim.nonhand.sample_nonhand`; `sim.episode.run_sample` runs it
with seeds from ``(seed, i, attempt)`` only, so the bytes never depend on which worker ran what.
"""

from __future__ import annotations

import ctypes
import os
import signal
from collections import Counter
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from sim.contactors import ContactorSpec, PressPlan
from sim.episode import EpisodeContext, Maker, run_sample
from sim.gen_config import GenerateConfig, is_mesh_path
from sim.generate_hands import hand_maker
from sim.hand import HandConfig
from sim.nonhand import sample_nonhand
from sim.parts import W0_REGION, W0_TILING, Part, custom_part, get_part
from sim.subjects import Subject, sample_subjects
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

    def make_scaled(rng: np.random.Generator) -> tuple[ContactorSpec, PressPlan]:
        spec, plan = make(rng)
        return spec, replace(plan, durations_s=tuple(d * factor for d in plan.durations_s))

    return make_scaled


def build_state(cfg: GenerateConfig, ctx: EpisodeContext | None = None) -> WorkerState:
    """A worker's state for ``cfg`` (``ctx`` reused when given, e.g. the parent's)."""
    ctx = ctx or EpisodeContext(cfg.episode, part=build_part(cfg))
    subjects = subject_pool(cfg)
    k = cfg.instances_per_kind
    return WorkerState(
        cfg,
        ctx,
        subjects,
        hand=scaled(hand_maker(subjects, ctx), cfg.duration_scale),
        nonhand=scaled(lambda rng: sample_nonhand(rng, k), cfg.duration_scale),
    )


def init_worker(cfg: GenerateConfig, ctx: EpisodeContext | None = None) -> None:
    """Build this process's state once (kept when a forked worker inherits the same config)."""
    global _STATE
    if _STATE is None or _STATE.cfg != cfg:
        _STATE = build_state(cfg, ctx)


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


def sample_at(i: int, state: WorkerState) -> tuple[Sample, Counter]:
    """Sample ``i`` of the dataset and its reject counts by reason."""
    cfg = state.cfg
    make = state.hand if is_hand_index(i, cfg.hand_fraction) else state.nonhand
    sample, rejects = run_sample(i, cfg.seed, state.ctx, make, cfg.keep_sequences)
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
    """A Ray actor holding one worker state (see `sim.sampler`)."""

    def __init__(self, cfg: GenerateConfig) -> None:
        init_worker(cfg)

    def make_chunk(self, k: int) -> tuple[int, list[Sample], dict[str, int]]:
        return make_chunk(k)
