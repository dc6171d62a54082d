"""Where the chunks of a generation run are computed: in this process, a process pool, or Ray.

Every executor yields ``(k, samples, rejects)`` for the chunks ``todo`` as they finish, from
`sim.generate.sampler.make_chunk`; which worker computed which chunk never changes the bytes, since
sample ``i`` depends only on ``(config, i)``. A pool keeps at most ``2 × workers`` chunks in flight,
so memory stays flat however many chunks there are.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from pathlib import Path

import numpy as np

from sim.episode.runner import EpisodeContext
from sim.generate.config import GenerateConfig
from sim.generate.sampler import RayWorker, init_worker, make_chunk, pool_worker_init
from tactile.errors import ConfigError

ChunkResult = tuple[int, list[dict[str, np.ndarray]], dict[str, int]]


def default_workers() -> int:
    """All the cores this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


def run_chunks(
    make_chunk: Callable[[int], ChunkResult],
    todo: list[int],
    workers: int,
    *,
    initializer: Callable[..., None] | None = None,
    initargs: tuple = (),
    mp_context: str | None = None,
) -> Iterator[ChunkResult]:
    """Compute chunks ``todo`` with ``workers`` processes; yield results as they finish.

    At most ``2 × workers`` chunks are in flight. With ``workers == 1`` everything runs in this
    process (after calling ``initializer``), which is easiest to debug and profile.
    ``mp_context``: how workers start ("spawn", "fork"; None: the platform's default).
    """
    if workers < 1:
        raise ConfigError(f"workers must be >= 1, got {workers}")
    if workers == 1:
        if initializer is not None:
            initializer(*initargs)
        for k in todo:
            yield make_chunk(k)
        return
    pending: set[Future] = set()
    queue = iter(todo)
    context = multiprocessing.get_context(mp_context) if mp_context else None
    with ProcessPoolExecutor(
        workers, mp_context=context, initializer=initializer, initargs=initargs
    ) as pool:
        for k in queue:
            pending.add(pool.submit(make_chunk, k))
            if len(pending) >= 2 * workers:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                yield from (f.result() for f in done)
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            yield from (f.result() for f in done)


def chunk_results(
    cfg: GenerateConfig, ctx: EpisodeContext, todo: list[int], workers: int, ray: str | None
) -> Iterator[ChunkResult]:
    """Chunk results from the chosen executor (in-process, process pool, or Ray actors)."""
    init_worker(cfg, ctx)  # forked workers inherit it; Ray actors and spawned ones rebuild it
    if ray:
        return run_chunks_ray(cfg, todo, workers, ray)
    if workers == 1:
        return run_chunks(make_chunk, todo, 1)
    return run_chunks(
        make_chunk, todo, workers, initializer=pool_worker_init, initargs=(cfg, os.getpid())
    )


def run_chunks_ray(
    cfg: GenerateConfig, todo: list[int], workers: int, address: str
) -> Iterator[ChunkResult]:
    """Compute chunks ``todo`` on ``workers`` Ray actors; yield results as they finish.

    ``address`` "local" starts a local instance with ``workers`` CPUs; anything else is passed to
    ``ray.init`` (e.g. "auto"). The nodes need handskin installed (same code: same bytes).
    """
    try:  # optional: ray (the ray extra)
        import ray
        from ray.util import ActorPool
    except ImportError as err:
        raise ConfigError("--ray needs the ray extra: pip install 'handskin[ray]'") from err
    started = not ray.is_initialized()
    if started:
        root = str(Path(__file__).resolve().parent.parent)
        env = {"env_vars": {"PYTHONPATH": root}}
        kw = {"num_cpus": workers} if address == "local" else {"address": address}
        ray.init(**kw, runtime_env=env, include_dashboard=False, log_to_driver=False)
    try:
        actor = ray.remote(num_cpus=1)(RayWorker)
        pool = ActorPool([actor.remote(cfg) for _ in range(max(1, min(workers, len(todo))))])
        yield from pool.map_unordered(lambda a, k: a.make_chunk.remote(k), todo)
    finally:
        if started:
            ray.shutdown()
