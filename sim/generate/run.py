"""Dataset generation: chunks of samples computed in parallel, written atomically, merged once.

Sample ``i`` depends only on ``(config, i)``: its class comes from
`sim.generate.sampler.is_hand_index`, its random draws from ``SeedSequence(seed, spawn_key=(i,
attempt))``. Workers (`sim.generate.executors`) compute whole chunks and return them; the parent
writes each chunk atomically (so Ray workers on other machines need no shared disk), shows a
progress bar with samples/s, ETA and rejects by reason, and merges at the end. A killed run resumes:
complete chunks are skipped, and the merged file has the same bytes as an uninterrupted run. A shard
(`sim.generate.shards`) computes every n-th chunk and leaves the merge to
`sim.generate.shards.merge_shards`.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

from tqdm import tqdm

from sim.contactors.spec import ACTIONS
from sim.episode.runner import EpisodeContext
from sim.generate.config import (
    GenerateConfig,
    generator_version,
    refuse_other_backend,
    refuse_other_code,
)
from sim.generate.executors import ChunkResult, chunk_results, default_workers
from sim.generate.sampler import build_part
from sim.generate.shards import shard_chunks
from tactile.dataset.folder import chunk_path, list_chunks
from tactile.dataset.manifest import claim_folder, make_manifest
from tactile.dataset.writer import DatasetWriter
from tactile.errors import ConfigError, require_folder
from tactile.files import disk_error, require_writable, writing


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


class ChunkSource(Protocol):
    """Another backend's chunks (`sim.warp.run.WarpChunks`): ``source(cfg, ctx, todo, workers,
    note)`` yields (chunk, samples, rejects) for the chunks ``todo`` (``note`` hears of its
    batches); ``attrs``: what the dataset records of the simulator."""

    attrs: dict[str, str]

    def __call__(
        self,
        cfg: GenerateConfig,
        ctx: EpisodeContext,
        todo: list[int],
        workers: int,
        note: Callable[[str], None],
    ) -> Iterator[ChunkResult]: ...


def open_writer(
    cfg: GenerateConfig, out: Path, ctx: EpisodeContext, simulator: dict[str, str] | None = None
) -> DatasetWriter:
    """The dataset writer of ``cfg`` in ``out`` (refuses a folder of another configuration);
    ``simulator``: attributes another backend records (`ChunkSource.attrs`)."""
    attrs = ctx.skin.readout().attrs() | {"actions": list(ACTIONS)} | (simulator or {})
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
    source: ChunkSource | None = None,
) -> RunReport:
    """Generate (or resume) the dataset of ``cfg`` in folder ``out``; merge when complete.

    workers : processes (default all cores; 1 = in this process) or Ray actors. shard : (i, n),
    compute only chunks k with k % n == i (no merge unless n == 1). ray : None (local processes),
    "local" (start a local Ray instance) or a Ray address ("auto", "ray://host:10001").
    source : the chunks of another backend than C MuJoCo's (``cfg.backend == "warp"``: run it
    with `sim.warp.run.generate`, which gives its source). The bytes of ``dataset.h5`` depend on
    ``cfg`` and the code only (on the warp backend: on its CPU device).
    """
    out = Path(out)
    t0 = time.perf_counter()
    _check_backend(cfg, ray, source)
    require_folder(out, fix="give a folder (new, or a dataset to resume)")
    require_writable(out, "--out", folder=True)
    ctx = EpisodeContext(cfg.episode, part=build_part(cfg))  # checks the part's taxel count
    _claim(cfg, out, workers)
    with writing(out / "chunks", fix="free space there and rerun the same command"):
        writer = open_writer(cfg, out, ctx, None if source is None else source.attrs)
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
        if source is None:
            results = chunk_results(cfg, ctx, todo, n_workers, ray)
        else:
            results = source(cfg, ctx, todo, n_workers, note=bar.bar.set_postfix_str)
        for k, samples, rejects in results:
            try:
                writer.write_chunk(k, samples, rejects=rejects)
            except OSError as err:
                fix = "free space there and rerun the same command: it resumes from the chunks"
                raise disk_error(err, chunk_path(out, k), space_needed(cfg, out), fix) from err
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


def space_needed(cfg: GenerateConfig, out: Path) -> float | None:
    """Bytes still to write to finish ``out`` (the chunks to go and the merged file), from the
    mean size of the chunks on disk; None before the first chunk."""
    sizes = [chunk_path(out, k).stat().st_size for k in list_chunks(out)]
    if not sizes:
        return None
    return sum(sizes) / len(sizes) * (2 * cfg.n_chunks - len(sizes))


def _check_backend(cfg: GenerateConfig, ray: str | None, source: ChunkSource | None) -> None:
    """ConfigError for a run another backend's source must make, or one it cannot."""
    if (cfg.backend != "mujoco" or source is not None) and ray:
        raise ConfigError("--ray runs the C backend only; drop --ray or use --backend mujoco")
    if cfg.backend != "mujoco" and source is None:
        raise ConfigError(
            f"backend = {cfg.backend!r} runs through sim.warp.run.generate (as handskin generate "
            "--backend warp does); this function runs the C backend"
        )


def _claim(cfg: GenerateConfig, out: Path, workers: int | None) -> None:
    """Check the run's arguments and claim ``out`` (manifest written first) before any work."""
    if workers is not None and workers < 1:
        raise ConfigError(f"workers = {workers} is out of range; allowed >= 1")
    manifest = make_manifest(cfg, cfg.part_id(), generator_version(), cfg.seed)
    refuse_other_backend(out, manifest)
    refuse_other_code(out, manifest)
    with writing(out / "manifest.json"):
        claim_folder(out, manifest)
