"""Dataset generation: chunks of samples computed in parallel, written atomically, merged once.

Sample ``i`` depends only on ``(config, i)``: its class comes from :func:`is_hand_index`, its random
draws from ``SeedSequence(seed, spawn_key=(i, attempt))``. Workers compute whole chunks and return
them; the parent writes each chunk atomically (so Ray workers on other machines need no shared
disk), keeps at most ``2 × workers`` chunks in flight (memory stays flat), shows a progress bar with
samples/s, ETA and rejects by reason, and merges at the end. A killed run resumes: complete chunks
are skipped, and the merged file has the same bytes as an uninterrupted run.
"""

from __future__ import annotations

import os
import time
from collections import Counter
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from sim.gen_config import GenerateConfig, generator_version, refuse_other_code
from tactile.errors import ConfigError, require_folder

Sample = dict[str, np.ndarray]
ChunkResult = tuple[int, list[Sample], dict[str, int]]


def is_hand_index(i: int, hand_fraction: float) -> bool:
    """Whether sample ``i`` is a hand contact: a Bresenham sequence, exact over every prefix.

    Over samples 0..n-1 exactly ``floor(n · hand_fraction)`` are hands, evenly interleaved, and
    the answer for ``i`` does not depend on ``n`` (so a dataset can be extended or sharded).
    """
    return int(np.floor((i + 1) * hand_fraction)) - int(np.floor(i * hand_fraction)) == 1


def chunk_ranges(n: int, chunk_size: int) -> list[tuple[int, int, int]]:
    """``(k, start, stop)`` of every chunk of ``n`` samples."""
    return [(k, s, min(s + chunk_size, n)) for k, s in enumerate(range(0, n, chunk_size))]


def default_workers() -> int:
    """All the cores this process may use."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1


@dataclass
class Progress:
    """Running totals shown in the progress bar."""

    bar: tqdm
    rejects: Counter

    def update(self, n_samples: int, rejects: dict[str, int]) -> None:
        self.rejects.update(rejects)
        self.bar.update(n_samples)
        if self.rejects:
            self.bar.set_postfix_str(
                "rejected " + ", ".join(f"{k} {v}" for k, v in sorted(self.rejects.items()))
            )


def run_chunks(
    make_chunk: Callable[[int], ChunkResult],
    todo: list[int],
    workers: int,
    *,
    initializer: Callable[..., None] | None = None,
    initargs: tuple = (),
) -> Iterator[ChunkResult]:
    """Compute chunks ``todo`` with ``workers`` processes; yield results as they finish.

    At most ``2 × workers`` chunks are in flight. With ``workers == 1`` everything runs in this
    process (after calling ``initializer``), which is easiest to debug and profile.
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
    with ProcessPoolExecutor(workers, initializer=initializer, initargs=initargs) as pool:
        for k in queue:
            pending.add(pool.submit(make_chunk, k))
            if len(pending) >= 2 * workers:
                done, pending = wait(pending, return_when=FIRST_COMPLETED)
                yield from (f.result() for f in done)
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            yield from (f.result() for f in done)


def progress_bar(total: int, initial: int, desc: str, enabled: bool = True) -> Progress:
    """A tqdm bar over samples, starting at the samples already on disk."""
    bar = tqdm(
        total=total,
        initial=initial,
        desc=desc,
        unit="sample",
        disable=not enabled,
        smoothing=0.1,
        dynamic_ncols=True,
    )
    return Progress(bar, Counter())


def out_dir_is_free(out: Path) -> None:
    """Refuse an output path that is, or lies under, a file, before any work starts."""
    require_folder(out, fix="give a folder (new, or a dataset to resume)")


# ------------------------------------------------------------------ the generation run


def parse_shard(text: str) -> tuple[int, int]:
    """``"i/n"`` -> (i, n) with 0 <= i < n; ConfigError otherwise."""
    try:
        i, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise ConfigError(f"--shard {text!r}: expected i/n, e.g. 0/4") from None
    if not 0 <= i < n:
        raise ConfigError(f"--shard {text!r}: need 0 <= i < n")
    return i, n


def shard_chunks(n_chunks: int, shard: tuple[int, int]) -> list[int]:
    """Chunks of shard ``(i, n)``: every n-th chunk starting at i (balanced, any n)."""
    return list(range(shard[0], n_chunks, shard[1]))


@dataclass(frozen=True)
class RunReport:
    """Outcome of `generate`: where, how much, how fast, and the rejected episodes by reason."""

    out: Path
    dataset: Path | None  # dataset.h5, or None for a shard (merge with `merge_shards`)
    n_computed: int  # samples computed by this run (resumed chunks excluded)
    n_samples: int  # samples of this run's chunks on disk (computed + resumed)
    wall_s: float  # wall time of this run, s (including the merge)
    rejects: dict[str, int]

    @property
    def samples_per_s(self) -> float:
        return self.n_computed / self.wall_s if self.wall_s > 0 else 0.0


def open_writer(cfg: GenerateConfig, out: Path, ctx):
    """The dataset writer of ``cfg`` in ``out`` (refuses a folder of another configuration)."""
    from sim.contactors import ACTIONS
    from tactile.dataset import DatasetWriter

    attrs = ctx.skin.readout().attrs() | {"actions": list(ACTIONS)}
    return DatasetWriter(
        out,
        config=cfg,
        part=cfg.part_id(),
        generator_version=generator_version(),
        seed=cfg.seed,
        tmap=ctx.tmap,
        layout=ctx.part.layout,
        attrs=attrs,
        seq_len=cfg.sequence_frames if cfg.keep_sequences else None,
    )


def generate(
    cfg: GenerateConfig,
    out: str | Path,
    *,
    workers: int | None = None,
    shard: tuple[int, int] = (0, 1),
    ray: str | None = None,
    progress: bool = True,
) -> RunReport:
    """Generate (or resume) the dataset of ``cfg`` in folder ``out``; merge when complete.

    workers : processes (default all cores; 1 = in this process) or Ray actors. shard : (i, n),
    compute only chunks k with k % n == i (no merge unless n == 1). ray : None (local processes),
    "local" (start a local Ray instance) or a Ray address ("auto", "ray://host:10001").
    The bytes of ``dataset.h5`` depend on ``cfg`` and the code only.
    """
    from sim.episode import EpisodeContext
    from sim.sampler import build_part

    out = Path(out)
    t0 = time.perf_counter()
    ctx = EpisodeContext(cfg.episode, part=build_part(cfg))  # checks the part's taxel count
    _claim(cfg, out, workers)
    writer = open_writer(cfg, out, ctx)
    mine = shard_chunks(cfg.n_chunks, shard)
    done = set(writer.complete_chunks())
    todo = [k for k in mine if k not in done]
    sizes = {k: min(cfg.chunk_size, cfg.n - k * cfg.chunk_size) for k in mine}
    n_workers = max(1, min(workers or default_workers(), len(todo)))
    bar = progress_bar(
        sum(sizes.values()),
        sum(sizes[k] for k in mine if k in done),
        f"{out.name} ({n_workers} {'Ray actors' if ray else 'workers'})",
        progress,
    )
    with bar.bar:
        for k, samples, rejects in _results(cfg, ctx, todo, n_workers, ray):
            writer.write_chunk(k, samples, rejects=rejects)
            bar.update(len(samples), rejects)
    dataset = writer.merge(n_chunks=cfg.n_chunks) if shard[1] == 1 else None
    return RunReport(
        out,
        dataset,
        sum(sizes[k] for k in todo),
        sum(sizes.values()),
        time.perf_counter() - t0,
        dict(sorted(bar.rejects.items())),
    )


def _claim(cfg: GenerateConfig, out: Path, workers: int | None) -> None:
    """Check the run's arguments and claim ``out`` (manifest written first) before any work."""
    from tactile.dataset.manifest import claim_folder, make_manifest

    out_dir_is_free(out)
    if workers is not None and workers < 1:
        raise ConfigError(f"workers = {workers} is out of range; allowed >= 1")
    manifest = make_manifest(cfg, cfg.part_id(), generator_version(), cfg.seed)
    refuse_other_code(out, manifest)
    claim_folder(out, manifest)


def _results(
    cfg: GenerateConfig, ctx, todo: list[int], workers: int, ray: str | None
) -> Iterator[ChunkResult]:
    """Chunk results from the chosen executor (in-process, process pool, or Ray actors)."""
    from sim.sampler import init_worker, make_chunk, pool_worker_init

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
    try:
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
        from sim.sampler import RayWorker

        actor = ray.remote(num_cpus=1)(RayWorker)
        pool = ActorPool([actor.remote(cfg) for _ in range(max(1, min(workers, len(todo))))])
        yield from pool.map_unordered(lambda a, k: a.make_chunk.remote(k), todo)
    finally:
        if started:
            ray.shutdown()


def merge_shards(shards: Sequence[str | Path], out: str | Path) -> Path:
    """Merge shard folders of one configuration into ``out`` (new, empty, or one of them).

    Every shard must carry the same fingerprint (DataError otherwise, nothing touched); the
    chunks are copied into ``out/chunks`` (atomically, skipping those present) and merged into
    ``out/dataset.h5`` — the same bytes as a single run of that configuration.
    """
    import shutil

    from tactile.dataset.h5io import atomic_path
    from tactile.dataset.manifest import claim_folder, differing_keys, read_manifest
    from tactile.dataset.merge import merge_chunks
    from tactile.dataset.writer import CHUNKS, STATIC, chunk_path, list_chunks
    from tactile.errors import DataError

    out, dirs = Path(out), [Path(d) for d in shards]
    manifests = [read_manifest(d) for d in dirs]
    for d, m in zip(dirs[1:], manifests[1:], strict=True):
        if m["fingerprint"] != manifests[0]["fingerprint"]:
            keys = differing_keys(manifests[0]["config"], m["config"])
            raise DataError(
                f"{d} is a shard of another dataset than {dirs[0]} (differing keys: "
                f"{', '.join(keys) or 'part/seed/generator_version'}); not merged"
            )
    claim_folder(out, manifests[0])
    (out / CHUNKS).mkdir(exist_ok=True)
    for d in dirs:
        names = [STATIC] + [chunk_path(d, k).name for k in list_chunks(d)]
        for name in names:
            src, dst = d / CHUNKS / name, out / CHUNKS / name
            if src.exists() and not dst.exists():
                with atomic_path(dst) as tmp:
                    shutil.copyfile(src, tmp)
    cfg = manifests[0]["config"]
    return merge_chunks(out, n_chunks=-(-cfg["n"] // cfg["chunk_size"]))
