"""Merge a dataset folder's chunks into ``dataset.h5`` (+ ``info.json``), streaming, reproducibly.

The merge reads one chunk at a time (memory flat in the number of chunks), writes the fields
stacked on axis 0, the train/test split (:mod:`tactile.dataset.splits`, seeded by the manifest's
seed), the map and layout once, and the root attributes. Nothing in it depends on time or paths,
so merging the same chunks twice gives the same bytes.
"""

from __future__ import annotations

import platform
import shutil
import zlib
from importlib import metadata
from pathlib import Path

import h5py
import numpy as np

import tactile.dataset.h5io as h5io
from tactile.dataset.damage import open_h5, read_or_name, repair_hint
from tactile.dataset.folder import CHUNKS, DATASET, INFO, STATIC, chunk_path, list_chunks
from tactile.dataset.h5io import json_attr
from tactile.dataset.manifest import read_manifest, record_content
from tactile.dataset.schema import BY_NAME, Dims, info_fields
from tactile.dataset.splits import METHODS, TRAIN_FRACTION, split_indices
from tactile.errors import DataError
from tactile.files import disk_error, remove_stale
from tactile.images.labels import CLASS_NAMES, N_CLASSES

PACKAGES = ("numpy", "h5py", "scipy", "scikit-image", "mujoco", "handskin")
ATTR_DOCS = {
    "skin_counts_per_pa": "float, counts/Pa: nominal skin gain (pressure_from_raw)",
    "skin_baseline_counts": "float or (N,) float, counts: untouched reading (pressure_from_raw)",
    "skin_drift_counts_per_s": "float or (N,) float, counts/s: baseline drift (pressure_from_raw)",
    "skin_noise_floor_counts": "float, counts: signals at or below it read 0 (pressure_from_raw)",
    "actions": "list of str: names of the `action` indices",
}


def versions() -> dict[str, str | None]:
    """Versions of Python and the packages that shape the data (None when not installed).

    Read from package metadata: nothing is imported (in particular not mujoco).
    """
    out: dict[str, str | None] = {"python": platform.python_version()}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def _chunks_to_merge(folder: Path, n_chunks: int | None) -> list[int]:
    done = list_chunks(folder)
    if not done:
        raise DataError(f"{folder}: no complete chunks to merge. Fix: run the generator first")
    expected = done[-1] + 1 if n_chunks is None else int(n_chunks)
    missing = sorted(set(range(expected)) - set(done))
    extra = sorted(set(done) - set(range(expected)))
    if missing or extra:
        raise DataError(
            f"{folder}: chunk(s) {missing[:5]} missing (of {expected}); unexpected {extra[:5]}. "
            "Fix: resume the generator with the same configuration to write them"
        )
    return done


def _scan(folder: Path, ks: list[int]) -> tuple[list[int], dict[str, tuple[int, ...]]]:
    """Samples per chunk and the per-sample shape of every field (equal in all chunks)."""
    counts, shapes = [], None
    for k in ks:
        with open_h5(chunk_path(folder, k)) as f:
            got = {n: f[BY_NAME[n].path].shape[1:] for n in json_attr(f, "fields")}
            counts.append(int(f.attrs["n_samples"]))
        if shapes is not None and got != shapes:
            raise DataError(
                f"{chunk_path(folder, k)}: fields/shapes {got} differ from chunk 0's {shapes}. "
                "Fix: delete the odd chunk and resume"
            )
        shapes = got
    return counts, shapes or {}


class _Stats:
    """Per-sample ids, class counts and rejects collected while streaming."""

    def __init__(self) -> None:
        names = ("is_hand", "subject_id", "instance_id", "contact_subject", "contact_instance")
        self.ids: dict[str, list[np.ndarray]] = {name: [] for name in names}
        self.pixels = np.zeros(N_CLASSES, np.int64)
        self.rejects: dict[str, int] = {}

    def add(self, f: h5py.File, fields: dict) -> None:
        path = Path(f.filename)
        for name in self.ids:
            if name in fields:
                self.ids[name].append(read_or_name(f[BY_NAME[name].path], name, path))
        if "label_image" in fields:
            labels = read_or_name(f[BY_NAME["label_image"].path], "label_image", path)
            self.pixels += np.bincount(labels.ravel(), minlength=N_CLASSES)[:N_CLASSES]
        for reason, n in json_attr(f, "rejects").items():
            self.rejects[reason] = self.rejects.get(reason, 0) + int(n)

    def column(self, name: str) -> np.ndarray | None:
        return np.concatenate(self.ids[name]) if self.ids[name] else None

    def class_balance(self) -> dict[str, object]:
        out: dict[str, object] = {}
        hand = self.column("is_hand")
        if hand is not None:
            out["samples"] = {"hand": int(hand.sum()), "non_hand": int((hand == 0).sum())}
        if self.pixels.any():
            out["label_image_pixels"] = dict(zip(CLASS_NAMES, self.pixels.tolist(), strict=True))
        return out


def copy_sample_chunks(src: h5py.Dataset, dst: h5py.Dataset, start: int) -> bool:
    """Copy ``src``'s samples into ``dst`` from row ``start`` as their stored, compressed HDF5
    chunks, when both hold one sample per chunk through the same filters (the bytes a fresh
    compression would write, without recompressing); False, copying nothing, otherwise. Each
    chunk's deflate stream is checked (its adler32) on the way, and a damaged one is named."""
    same = _filters(src) == _filters(dst)
    if not (same and _one_sample_chunks(src) and _one_sample_chunks(dst)):
        return False
    if src.compression != "gzip" or not src.fletcher32:
        return False
    zero = (0,) * (src.ndim - 1)
    for j in range(len(src)):
        mask, data = src.id.read_direct_chunk((j, *zero))
        try:
            zlib.decompress(data[:-4])  # the payload; the last 4 bytes are the fletcher32
        except zlib.error as err:
            path, field = Path(src.file.filename), src.name.rsplit("/", 1)[-1]
            read_or_name(src, field, path, j)  # names the damaged sample (DataError)
            raise DataError(
                f"{path}: field {field!r} of sample {j} cannot be read (damaged compressed "
                f"data). {repair_hint(path)}"
            ) from err
        dst.id.write_direct_chunk((start + j, *zero), data, mask)
    return True


def _one_sample_chunks(ds: h5py.Dataset) -> bool:
    return ds.chunks is not None and ds.ndim >= 2 and ds.chunks == (1, *ds.shape[1:])


def _filters(ds: h5py.Dataset) -> tuple[object, ...]:
    return ds.dtype, ds.compression, ds.compression_opts, ds.shuffle, ds.fletcher32


def _stream(f: h5py.File, folder: Path, ks: list[int], counts: list[int], shapes: dict) -> _Stats:
    total, stats = sum(counts), _Stats()
    out = {}
    for name, shape in shapes.items():
        parent, leaf = BY_NAME[name].path.split("/")
        dtype = BY_NAME[name].dtype
        out[name] = h5io.stacked_dataset(h5io.group(f, parent), leaf, total, shape, dtype)
    start = 0
    for k, n in zip(ks, counts, strict=True):
        path = chunk_path(folder, k)
        with open_h5(path) as src:
            for name in shapes:
                ds = src[BY_NAME[name].path]
                if not copy_sample_chunks(ds, out[name], start):
                    out[name][start : start + n] = read_or_name(ds, name, path)
            stats.add(src, shapes)
        h5io.check_written(f)  # a full disk stops the merge here, not at the end
        start += n
    return stats


def merge_chunks(
    folder: str | Path,
    *,
    n_chunks: int | None = None,
    train_fraction: float = TRAIN_FRACTION,
    remove_chunks: bool = False,
) -> Path:
    """Merge ``folder/chunks/chunk_*.h5`` into ``folder/dataset.h5`` and write ``info.json``.

    The train/test split uses the manifest's seed and its configuration's ``split`` method
    (``tactile.dataset.splits.METHODS``; "greedy" when absent), recorded as ``split_method``.

    The chunks must be 0..K-1 without gaps (K = ``n_chunks`` when given, so an unfinished run is
    refused) and agree in fields and shapes. ``dataset.h5`` is
    replaced atomically; ``remove_chunks`` deletes ``chunks/`` afterwards. Returns the file path.
    """
    folder = Path(folder)
    manifest = read_manifest(folder)
    method = str((manifest.get("config") or {}).get("split", "greedy"))
    if method not in METHODS:
        raise DataError(
            f"{folder}: the manifest's split method {method!r} is unknown; choose one "
            f"of {', '.join(METHODS)} in its configuration"
        )
    if not (folder / CHUNKS / STATIC).exists():
        raise DataError(f"{folder}: {CHUNKS}/{STATIC} is missing. Fix: rerun the generator")
    ks = _chunks_to_merge(folder, n_chunks)
    counts, shapes = _scan(folder, ks)
    info: dict[str, object] = {}

    def fill(f: h5py.File) -> None:
        stats = _stream(f, folder, ks, counts, shapes)
        several = stats.column("contact_subject") is not None  # every contact's groups
        split = split_indices(
            stats.column("is_hand"),
            stats.column("contact_subject" if several else "subject_id"),
            stats.column("contact_instance" if several else "instance_id"),
            train_fraction=train_fraction,
            seed=int(manifest["seed"]),
            method=method,
        )
        g = h5io.group(f, "splits")
        h5io.plain_dataset(g, "train", split.train.astype(np.int64))
        h5io.plain_dataset(g, "test", split.test.astype(np.int64))
        extra = _copy_static(folder / CHUNKS / STATIC, f)
        attrs = _root_attrs(manifest, stats, split.report, sum(counts), train_fraction, method)
        h5io.set_attrs(f, {**extra, **attrs})
        info.update(_info(manifest, attrs, shapes, extra, f["map"].attrs["dims"]))

    path = folder / DATASET
    remove_stale(folder)  # temporary files of a merge that was killed
    try:
        h5io.write_h5(path, fill)
        h5io.write_json(folder / INFO, info)
        record_content(folder)
    except OSError as err:
        need = sum(p.stat().st_size for p in (folder / CHUNKS).iterdir())
        raise disk_error(err, path, need, "free space there and merge again") from err
    if remove_chunks:
        shutil.rmtree(folder / CHUNKS)
    return path


def _copy_static(static: Path, f: h5py.File) -> dict:
    """Copy the map of ``chunks/static.h5`` into ``f``; return its root attrs."""
    with open_h5(static) as src:
        try:
            h5io.copy_tree(src["map"], h5io.group(f, "map"))
        except OSError as err:
            why = str(err).splitlines()[0]
            msg = f"{static}: the map cannot be read ({why}). {repair_hint(static)}"
            raise DataError(msg) from None
        return dict(src.attrs)


def _root_attrs(
    manifest: dict, stats: _Stats, report: dict, n: int, fraction: float, method: str
) -> dict:
    return {
        "format": manifest["format"],
        "fingerprint": manifest["fingerprint"],
        "config": h5io.canonical_json(manifest["config"]),
        "versions": versions(),
        "generator_version": manifest["generator_version"],
        "seed": int(manifest["seed"]),
        "part": manifest["part"],
        "class_balance": stats.class_balance(),
        "rejects": dict(sorted(stats.rejects.items())),
        "split_report": report,
        "train_fraction": float(fraction),
        "split_method": method,
        "n_samples": int(n),
    }


def _info(manifest: dict, attrs: dict, shapes: dict, extra: dict, dims: np.ndarray) -> dict:
    seq = shapes["seq_raw"][0] if "seq_raw" in shapes else None
    d = Dims(int(dims[0]), int(dims[1]), int(dims[2]), seq)
    keys = (
        "format",
        "fingerprint",
        "part",
        "seed",
        "generator_version",
        "n_samples",
        "class_balance",
        "rejects",
        "split_method",
        "split_report",
        "versions",
    )
    return {
        **{k: attrs[k] for k in keys},
        "dims": {"N": d.n_taxels, "H": d.height, "W": d.width, "T": d.seq_len},
        "fields": info_fields(tuple(shapes), d),
        "attrs": {k: ATTR_DOCS.get(k, "caller-defined") for k in sorted(extra)},
    }
