"""Shards of a generation run: ``generate --shard i/n`` computes every n-th chunk from i, and
`merge_shards` joins the shard folders into one dataset, the same bytes as a single run.

Every shard folder carries the run's manifest; shards of different configurations are refused
before anything is copied.
"""

from __future__ import annotations

import shutil
from collections.abc import Sequence
from pathlib import Path

from tactile.dataset.folder import CHUNKS, STATIC, chunk_path, list_chunks
from tactile.dataset.h5io import atomic_path
from tactile.dataset.manifest import claim_folder, differing_keys, read_manifest
from tactile.dataset.merge import merge_chunks
from tactile.errors import ConfigError, DataError
from tactile.files import remove_stale, writing


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


def merge_shards(shards: Sequence[str | Path], out: str | Path) -> Path:
    """Merge shard folders of one configuration into ``out`` (new, empty, or one of them).

    Every shard must carry the same fingerprint (DataError otherwise, nothing touched); the
    chunks are copied into ``out/chunks`` (atomically, skipping those present) and merged into
    ``out/dataset.h5`` — the same bytes as a single run of that configuration.
    """
    out, dirs = Path(out), [Path(d) for d in shards]
    manifests = [read_manifest(d) for d in dirs]
    for d, m in zip(dirs[1:], manifests[1:], strict=True):
        if m["fingerprint"] != manifests[0]["fingerprint"]:
            keys = differing_keys(manifests[0]["config"], m["config"])
            raise DataError(
                f"{d} is a shard of another dataset than {dirs[0]} (differing keys: "
                f"{', '.join(keys) or 'part/seed/generator_version'}); not merged"
            )
    with writing(out / CHUNKS):
        claim_folder(out, manifests[0])
        (out / CHUNKS).mkdir(exist_ok=True)
    remove_stale(out / CHUNKS)  # chunk copies of a merge that was killed
    for d in dirs:
        names = [STATIC] + [chunk_path(d, k).name for k in list_chunks(d)]
        for name in names:
            src, dst = d / CHUNKS / name, out / CHUNKS / name
            if src.exists() and not dst.exists():
                with writing(dst, fix="free space there and merge again"), atomic_path(dst) as tmp:
                    shutil.copyfile(src, tmp)
    cfg = manifests[0]["config"]
    whole = "n" in cfg and "chunk_size" in cfg  # a generated run's chunk count (not ingest's)
    try:
        return merge_chunks(out, n_chunks=-(-cfg["n"] // cfg["chunk_size"]) if whole else None)
    except DataError as err:
        raise _name_source(err, out, dirs) from None


def _name_source(err: DataError, out: Path, dirs: list[Path]) -> DataError:
    """``err`` naming the shard a damaged chunk was copied from (the copy is byte-exact)."""
    for d in dirs:
        for k in list_chunks(d):
            copy, src = chunk_path(out, k), chunk_path(d, k)
            if f"{copy}:" in str(err) and src != copy:
                what = str(err).split(" Fix: ")[0]
                return DataError(
                    f"{what} It is a byte-exact copy of {src}. Fix: delete both, rerun that "
                    f"shard's handskin generate --out {d} --shard ..., then merge again"
                )
    return err
