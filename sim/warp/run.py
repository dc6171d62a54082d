"""`handskin generate --backend warp`: `sim.generate.run.generate` with its chunks stepped as the
worlds of batched MuJoCo Warp models (`sim.warp.backend`).

    report = generate(cfg, "data/warp", warp=WarpOptions(worlds=256, device="cuda"))
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

from sim.episode.runner import EpisodeContext
from sim.generate import run
from sim.generate.config import GenerateConfig
from sim.generate.executors import ChunkResult
from sim.warp.options import WarpOptions, check_warp, simulator_label
from tactile.errors import ConfigError


@dataclass(frozen=True)
class WarpChunks:
    """The warp backend as a `sim.generate.run.ChunkSource`."""

    opts: WarpOptions

    @property
    def attrs(self) -> dict[str, str]:
        return {"simulator": simulator_label(self.opts)}

    def __call__(
        self,
        cfg: GenerateConfig,
        ctx: EpisodeContext,
        todo: list[int],
        workers: int,
        note: Callable[[str], None],
    ) -> Iterator[ChunkResult]:
        from sim.warp.backend import warp_chunk_results  # optional: mujoco-warp (the warp extra)

        return warp_chunk_results(cfg, ctx, todo, workers, self.opts, note=note)


def generate(
    cfg: GenerateConfig,
    out: str | Path,
    *,
    workers: int | None = None,
    shard: tuple[int, int] = (0, 1),
    progress: bool = True,
    warp: WarpOptions | None = None,
) -> run.RunReport:
    """`sim.generate.run.generate` of ``cfg`` (``backend = "warp"``) on the warp backend with
    options ``warp`` (None: the defaults), checked (packages, device) before any work."""
    if cfg.backend != "warp":
        raise ConfigError("--worlds, --device, --nconmax and --njmax need --backend warp")
    if cfg.mix.fraction > 0:
        raise ConfigError(
            "[mix] fraction > 0 (several contacts per sample) runs on the C backend only; "
            "use --backend mujoco or set [mix] fraction = 0"
        )
    warp = warp or WarpOptions()
    check_warp(warp)
    return run.generate(
        cfg, out, workers=workers, shard=shard, progress=progress, source=WarpChunks(warp)
    )
