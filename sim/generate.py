"""Dataset generation: chunks of samples computed in parallel, written atomically, merged once.

Sample ``i`` depends only on ``(config, i)``: its class comes from `sim.sampler.is_hand_index`,
its random draws from ``SeedSequence(seed, spawn_key=(i, attempt))``. Workers (`sim.executors`)
compute whole chunks and return them; the parent writes each chunk atomically (so Ray workers on
other machines need no shared disk), shows a progress bar with samples/s, ETA and rejects by
reason, and merges at the end. A killed run resumes: complete chunks are skipped, and the merged
file has the same bytes as an uninterrupted run. A shard (`sim.shards`) computes every n-th chunk
and leaves the merge to `sim.shards.merge_shards`.
"""

from __future__ import annotations

import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from sim.contactors import ACTIONS
from sim.episode import EpisodeContext
from sim.executors import ChunkResult, chunk_results, default_workers
from sim.gen_config import (
    GenerateConfig,
    generator_version,
    refuse_other_backend,
    refuse_other_code,
)
from sim.sampler import build_part
from sim.shards import shard_chunks
from sim.warp_options import WarpOptions, check_warp, simulator_label
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


def open_writer(
    cfg: GenerateConfig, out: Path, ctx: EpisodeContext, warp: WarpOptions | None = None
) -> DatasetWriter:
    """The dataset writer of ``cfg`` in ``out`` (refuses a folder of another configuration);
    a warp run also records its simulator (`sim.warp_options.simulator_label`)."""
    attrs = ctx.skin.readout().attrs() | {"actions": list(ACTIONS)}
    if warp is not None:
        attrs["simulator"] = simulator_label(warp)
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
    warp: WarpOptions | None = None,
) -> RunReport:
    """Generate (or resume) the dataset of ``cfg`` in folder ``out``; merge when complete.

    workers : processes (default all cores; 1 = in this process) or Ray actors. shard : (i, n),
    compute only chunks k with k % n == i (no merge unless n == 1). ray : None (local processes),
    "local" (start a local Ray instance) or a Ray address ("auto", "ray://host:10001").
    warp : options of ``cfg.backend == "warp"`` (None: defaults). The bytes of ``dataset.h5``
    depend on ``cfg`` and the code only (on the warp backend: on its CPU device).
    """
    out = Path(out)
    t0 = time.perf_counter()
    warp = _backend_options(cfg, ray, warp)
    require_folder(out, fix="give a folder (new, or a dataset to resume)")
    require_writable(out, "--out", folder=True)
    ctx = EpisodeContext(cfg.episode, part=build_part(cfg))  # checks the part's taxel count
    _claim(cfg, out, workers)
    with writing(out / "chunks", fix="free space there and rerun the same command"):
        writer = open_writer(cfg, out, ctx, warp)
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
        for k, samples, rejects in _results(cfg, ctx, todo, n_workers, ray, warp, bar.bar):
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


def _backend_options(
    cfg: GenerateConfig, ray: str | None, warp: WarpOptions | None
) -> WarpOptions | None:
    """The warp options of a warp run, checked (packages, device); None on the C backend."""
    if cfg.backend != "warp":
        if warp is not None:
            raise ConfigError("--worlds, --device, --nconmax and --njmax need --backend warp")
        return None
    if ray:
        raise ConfigError("--ray runs the C backend only; drop --ray or use --backend mujoco")
    if cfg.mix.fraction > 0:
        raise ConfigError(
            "[mix] fraction > 0 (several contacts per sample) runs on the C backend only; "
            "use --backend mujoco or set [mix] fraction = 0"
        )
    warp = warp or WarpOptions()
    check_warp(warp)
    return warp


def _results(
    cfg, ctx, todo, workers, ray, warp: WarpOptions | None, bar: tqdm
) -> Iterator[ChunkResult]:
    """Chunk results from the configured backend (the warp backend in one process also names
    its batches in the bar: a window of chunks is written at once)."""
    if warp is None:
        return chunk_results(cfg, ctx, todo, workers, ray)
    from sim.warp_backend import warp_chunk_results  # optional: mujoco-warp (the warp extra)

    return warp_chunk_results(cfg, ctx, todo, workers, warp, note=bar.set_postfix_str)


def _claim(cfg: GenerateConfig, out: Path, workers: int | None) -> None:
    """Check the run's arguments and claim ``out`` (manifest written first) before any work."""
    if workers is not None and workers < 1:
        raise ConfigError(f"workers = {workers} is out of range; allowed >= 1")
    manifest = make_manifest(cfg, cfg.part_id(), generator_version(), cfg.seed)
    refuse_other_backend(out, manifest)
    refuse_other_code(out, manifest)
    with writing(out / "manifest.json"):
        claim_folder(out, manifest)
