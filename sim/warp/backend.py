"""`handskin generate --backend warp`: a generation run's chunks from batched MuJoCo Warp worlds.

Chunks are computed in windows (`window_chunks`: about `WINDOW_BATCHES` batches' worth of
samples). In a window every sample ``i`` first tries attempt 0; the attempts of a round are
prepared exactly as on the C backend (`sim.episode.runner.select_attempt`: the maker and
`sim.episode.runner.start_episode` draw from `sim.episode.runner.episode_rng(seed, i, attempt)`),
grouped by structure family (`sim.warp.model.structure_digest`; every hand is one family), sorted by
length within a family and stepped in batches of at most ``worlds`` (`sim.warp.batch`). A failed
attempt (same checks and reasons as the C backend, as far as MJWarp exposes them) is retried with
the next attempt's seed in the next round. Kept attempts become samples through
`sim.episode.runner.make_sample`, so images and labels are made from the frames by the same code.

A world's trajectory does not depend on the other worlds of its batch, on its place there, on
the window or on the capacities (tests/sim/test_warp_backend.py checks it bit for bit on the
CPU device), so a dataset's bytes depend on the configuration only, for any ``--worlds`` and
``--workers``.
"""

from __future__ import annotations

import math
import os
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from functools import partial
from itertools import groupby

from sim.contactors.spec import ContactorSpec, PressPlan
from sim.episode.frames import Frames
from sim.episode.runner import (
    Attempt,
    EpisodeContext,
    EpisodeFailure,
    attempts_exhausted,
    check_contact,
    episode_rng,
    make_sample,
)
from sim.generate.config import GenerateConfig
from sim.generate.executors import run_chunks
from sim.generate.sampler import (
    WorkerState,
    current_state,
    init_worker,
    maker_at,
    pad_sequence,
    pool_worker_init,
    release_free_memory,
)
from sim.warp.batch import CapacityOverflow, WorldJob, run_batch
from sim.warp.jobs import JobMaker, KeyModel
from sim.warp.options import WarpOptions, check_warp
from tactile.errors import ConfigError

ChunkResult = tuple[int, list[dict], dict[str, int]]
WINDOW_BATCHES = 4  # a window holds about this many full batches of samples
MAX_GROWTH = 4  # derived capacities double at most this many times on overflow
_MAKER: JobMaker | None = None  # this process's, for its worker state's context and device


@dataclass
class Pending:
    """A sample of a window: its next attempt, rejects so far, and the kept attempt."""

    index: int
    attempt: int = 0
    rejects: Counter = field(default_factory=Counter)
    kept: Attempt | None = None


@dataclass
class Trial:
    """One attempt of a round: what was drawn, its seed, its prepared job and device model."""

    sample: Pending
    contactor: ContactorSpec | list[ContactorSpec]
    plan: PressPlan | list[PressPlan]
    ep_seed: int
    job: WorldJob
    key_model: KeyModel


def window_chunks(cfg: GenerateConfig, opts: WarpOptions) -> int:
    """Chunks per window: about `WINDOW_BATCHES` x ``worlds`` samples, at least one chunk."""
    return max(1, math.ceil(WINDOW_BATCHES * opts.worlds / cfg.chunk_size))


def warp_chunk_results(
    cfg: GenerateConfig,
    ctx: EpisodeContext,
    todo: list[int],
    workers: int,
    opts: WarpOptions,
    note: Callable[[str], None] | None = None,
) -> Iterator[ChunkResult]:
    """Chunk results of ``todo`` from windows run in this process (one worker; ``note`` hears
    of each batch) or in a pool of spawned processes (a fork would inherit warp's runtime)."""
    size = window_chunks(cfg, opts)
    windows = [todo[i : i + size] for i in range(0, len(todo), size)]
    workers = min(workers, len(windows))
    if workers <= 1:
        init_worker(cfg, ctx)
        for window in windows:
            yield from make_window(window, opts, note)
        return
    pool = run_chunks(
        partial(make_window, opts=opts),
        windows,
        workers,
        initializer=pool_worker_init,
        initargs=(cfg, os.getpid()),
        mp_context="spawn",
    )
    for results in pool:
        yield from results


def make_window(
    chunks: list[int], opts: WarpOptions, note: Callable[[str], None] | None = None
) -> list[ChunkResult]:
    """The chunk results of ``chunks`` (in order), computed in this process's worker state;
    ``note`` (a progress bar's postfix) hears of each batch."""
    check_warp(opts)
    state = current_state()
    maker = job_maker(state.ctx, opts.device)
    cfg = state.cfg
    spans = {k: range(k * cfg.chunk_size, min((k + 1) * cfg.chunk_size, cfg.n)) for k in chunks}
    samples = {i: Pending(i) for span in spans.values() for i in span}
    while todo := [s for s in samples.values() if s.kept is None]:
        trials = []
        for s in todo:
            try:
                trials.append(make_trial(state, maker, s))
            except EpisodeFailure as failure:  # a maker of several contacts found no room
                _reject(state, s, failure)
        outcomes = run_trials(trials, state.ctx, opts, note)
        for trial, outcome in zip(trials, outcomes, strict=True):
            settle(state, trial, outcome)
    out = [
        (k, [finish_sample(state, samples[i].kept) for i in span], _rejects(samples, span))
        for k, span in spans.items()
    ]
    release_free_memory()
    return out


def job_maker(ctx: EpisodeContext, device: str) -> JobMaker:
    """This process's `JobMaker` for ``ctx`` on ``device`` (kept across windows: its cache of
    contactor models is what makes a contactor's device model once per worker)."""
    global _MAKER
    if _MAKER is None or _MAKER.ctx is not ctx or _MAKER.device != device:
        _MAKER = JobMaker(ctx, device)
    return _MAKER


def make_trial(state: WorkerState, maker: JobMaker, s: Pending) -> Trial:
    """Sample ``s``'s next attempt, drawn and prepared as on the C backend (EpisodeFailure
    when the maker finds no room for several contacts)."""
    rng, ep_seed = episode_rng(state.cfg.seed, s.index, s.attempt)
    contactor, plan = maker_at(s.index, state)(rng)
    job, km = maker.prepare(contactor, plan, rng, keep_release=state.cfg.keep_sequences)
    return Trial(s, contactor, plan, ep_seed, job, km)


def settle(state: WorkerState, trial: Trial, outcome: Frames | EpisodeFailure) -> None:
    """Keep the trial's attempt, or count its failure and move its sample to the next one."""
    try:
        if isinstance(outcome, EpisodeFailure):
            raise outcome
        check_contact(state.ctx, outcome)
    except EpisodeFailure as failure:
        _reject(state, trial.sample, failure)
        return
    s = trial.sample
    s.kept = Attempt(trial.contactor, trial.plan, outcome, trial.ep_seed, Counter(s.rejects))


def _reject(state: WorkerState, s: Pending, failure: EpisodeFailure) -> None:
    """Count a failed attempt; ConfigError (as on the C backend) when it was the last."""
    s.rejects[failure.reason] += 1
    s.attempt += 1
    if s.attempt == state.ctx.cfg.max_attempts:
        raise attempts_exhausted(s.index, state.cfg.seed, state.ctx, s.rejects)


def finish_sample(state: WorkerState, a: Attempt) -> dict:
    """The dataset sample of a kept attempt, made as `sim.generate.sampler.sample_at` makes it."""
    cfg = state.cfg
    several = cfg.mix.fraction > 0  # as `sim.generate.sampler.sample_at`
    sample = make_sample(
        state.ctx, a.contactor, a.plan, a.frames, a.ep_seed, cfg.keep_sequences, several
    )
    return pad_sequence(sample, cfg.sequence_frames) if cfg.keep_sequences else sample


def _rejects(samples: dict[int, Pending], span: range) -> dict[str, int]:
    total: Counter = Counter()
    for i in span:
        total.update(samples[i].rejects)
    return dict(total)


def run_trials(
    trials: list[Trial],
    ctx: EpisodeContext,
    opts: WarpOptions,
    note: Callable[[str], None] | None = None,
) -> list[Frames | EpisodeFailure]:
    """Outcomes of ``trials`` (in their order): stepped by family, shortest plans together,
    in batches of at most ``opts.worlds``."""
    order = sorted(
        range(len(trials)),
        key=lambda t: (trials[t].key_model.digest, trials[t].job.n_frames, trials[t].sample.index),
    )
    batches = []
    for _, family in groupby(order, key=lambda t: trials[t].key_model.digest):
        members = list(family)
        batches += [members[lo : lo + opts.worlds] for lo in range(0, len(members), opts.worlds)]
    out: list = [None] * len(trials)
    for b, batch in enumerate(batches):
        if note is not None:
            note(f"warp batch {b + 1}/{len(batches)} ({len(batch)} worlds)")
        results = _run_with_room([trials[t] for t in batch], ctx, opts)
        for t, result in zip(batch, results, strict=True):
            out[t] = result
    return out


def _run_with_room(trials: list[Trial], ctx: EpisodeContext, opts: WarpOptions) -> list:
    """`run_batch` with the batch's capacities; derived ones double on overflow."""
    nconmax = opts.nconmax or max(t.key_model.nconmax for t in trials)
    njmax = opts.njmax or max(t.key_model.njmax for t in trials)
    jobs = [t.job for t in trials]
    for _ in range(MAX_GROWTH + 1):
        try:
            return run_batch(jobs, ctx.skin, ctx.cfg.active_pa, opts.device, nconmax, njmax)
        except CapacityOverflow as err:
            if opts.nconmax or opts.njmax:
                raise ConfigError(
                    f"--nconmax {nconmax} / --njmax {njmax} are too small for this scene: MJWarp "
                    f"overflowed ({err}). Fix: raise them, or leave them out (derived)"
                ) from err
            nconmax, njmax = 2 * nconmax, 2 * njmax
    raise ConfigError(
        f"MJWarp still overflows at {nconmax // 2} contacts and {njmax // 2} constraint rows per "
        "world. Fix: give --nconmax and --njmax explicitly"
    )
