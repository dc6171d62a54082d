"""The dataset folder's ``manifest.json``: what the data was made from, and its fingerprint.

The fingerprint is the sha256 of the canonical JSON (sorted keys, no spaces) of
``{"config", "part", "generator_version", "seed"}``. It is written before the first chunk; a run
pointed at a folder whose manifest differs is refused, so chunks of two configurations never mix.
Each merge adds ``content``: the sha256 and size of ``dataset.h5`` and ``info.json`` as written,
which ``handskin verify`` checks.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
from collections.abc import Mapping
from os import PathLike
from pathlib import Path

import numpy as np

from tactile.config import record
from tactile.dataset.folder import DATASET, INFO
from tactile.dataset.h5io import canonical_json, write_json
from tactile.errors import DataError

FORMAT = "handskin.dataset/1"
MANIFEST = "manifest.json"
IDENTITY = ("config", "part", "generator_version", "seed")
CONTENT = "content"  # {file name: {"sha256": hex, "bytes": int}} of the merged files


def jsonable(obj: object) -> object:
    """A JSON-ready copy: dataclasses -> dicts, tuples -> lists, numpy scalars/arrays -> Python,
    paths -> str. Raises DataError naming the first value JSON cannot hold."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return jsonable(record(obj))
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray | np.generic):
        return jsonable(obj.tolist())
    if isinstance(obj, PathLike):
        return str(obj)
    if obj is None or isinstance(obj, bool | int | float | str):
        if isinstance(obj, float) and not np.isfinite(obj):
            raise DataError(f"config value {obj} is not finite; JSON cannot hold it. Fix: use null")
        return obj
    raise DataError(f"config value {obj!r} ({type(obj).__name__}) is not JSON-serialisable")


def make_manifest(config: object, part: str, generator_version: str, seed: int) -> dict:
    """The manifest dict: format, identity fields (JSON-ready) and their fingerprint."""
    ident = {
        "config": jsonable(config),
        "part": str(part),
        "generator_version": str(generator_version),
        "seed": int(seed),
    }
    return {"format": FORMAT, "fingerprint": fingerprint_of(ident), **ident}


def fingerprint_of(manifest: Mapping[str, object]) -> str:
    """The sha256 of the canonical JSON of a manifest's ``IDENTITY`` fields: its fingerprint,
    unless the file was edited since it was written."""
    ident = {k: manifest.get(k) for k in IDENTITY}
    return hashlib.sha256(canonical_json(ident).encode("utf-8")).hexdigest()


def expected_chunks(manifest: Mapping[str, object]) -> int | None:
    """The chunks a generation run of ``manifest``'s configuration writes, ceil(n / chunk_size);
    None when its config holds no positive integer ``n`` and ``chunk_size`` (e.g. ingest's)."""
    config = manifest.get("config")
    n, size = (config.get(k) if isinstance(config, dict) else None for k in ("n", "chunk_size"))
    if not all(isinstance(v, int) and not isinstance(v, bool) and v > 0 for v in (n, size)):
        return None
    return -(-n // size)


def differing_keys(a: object, b: object, prefix: str = "") -> list[str]:
    """Dotted keys where two JSON-ready values differ (recursing into dicts)."""
    if isinstance(a, dict) and isinstance(b, dict):
        out: list[str] = []
        for key in sorted(set(a) | set(b)):
            sub = f"{prefix}.{key}" if prefix else str(key)
            if key not in a or key not in b:
                out.append(sub)
            else:
                out += differing_keys(a[key], b[key], sub)
        return out
    return [] if a == b else [prefix or "<value>"]


def read_manifest(folder: Path) -> dict:
    """The folder's manifest; DataError when missing or unreadable."""
    path = folder / MANIFEST
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        raise DataError(f"{path}: cannot read the dataset manifest ({err})") from err
    if not isinstance(data, dict) or data.get("format") != FORMAT or "fingerprint" not in data:
        raise DataError(f"{path} is not a {FORMAT} manifest. Fix: choose a new --out folder")
    return data


def claim_folder(folder: Path, manifest: dict) -> bool:
    """Make ``folder`` the home of ``manifest``'s dataset; True when resuming an existing one.

    An absent or empty folder gets the manifest (written atomically). A folder with the same
    fingerprint is resumed. Anything else — another fingerprint, or files but no manifest — is a
    DataError naming the differing keys and the fix; nothing in the folder is touched.
    """
    if folder.exists() and not folder.is_dir():
        raise DataError(f"{folder} is a file, not a dataset folder. Fix: choose a new --out folder")
    if not folder.exists() or not any(folder.iterdir()):
        folder.mkdir(parents=True, exist_ok=True)
        write_json(folder / MANIFEST, manifest)
        return False
    if not (folder / MANIFEST).exists():
        raise DataError(
            f"{folder} is not empty and has no {MANIFEST}: not a dataset folder. "
            "Fix: choose a new --out folder (or an empty one)"
        )
    old = read_manifest(folder)
    if old["fingerprint"] == manifest["fingerprint"]:
        return True
    keys = differing_keys({k: old.get(k) for k in IDENTITY}, {k: manifest[k] for k in IDENTITY})
    raise DataError(
        f"{folder} holds a dataset of another configuration: fingerprint {old['fingerprint'][:12]} "
        f"on disk, {manifest['fingerprint'][:12]} requested; differing keys: "
        f"{', '.join(keys) or 'format'}. Fix: write to a new --out folder (or delete this one)"
    )


def file_digest(path: Path) -> dict[str, object]:
    """{"sha256": hex digest, "bytes": size} of a file, read in 1 MiB blocks."""
    digest, size = hashlib.sha256(), 0
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            digest.update(block)
            size += len(block)
    return {"sha256": digest.hexdigest(), "bytes": size}


def record_content(folder: Path) -> None:
    """Write the digests of ``dataset.h5`` and ``info.json`` into the folder's manifest."""
    manifest = read_manifest(folder)
    manifest[CONTENT] = {name: file_digest(folder / name) for name in (DATASET, INFO)}
    write_json(folder / MANIFEST, manifest)
