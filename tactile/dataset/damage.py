"""Damaged bytes named: a read of ``dataset.h5`` or a chunk file that fails says which file,
which field and which sample, and how to get the data back.

    view = FieldView(h5file["samples/image"], "image", path)   # reads like the h5py.Dataset
    view[5]        # DataError: ds/dataset.h5: field 'image' of sample 5 cannot be read
                   # (checksum mismatch or damaged compressed data). Fix: rebuild it from its
                   # chunks: handskin merge ds --out ds

A read fails when HDF5's fletcher32 checksum or the gzip stream of a chunk does not hold; the
sample named is the first HDF5 chunk of the selection that fails on its own.
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from tactile.dataset.folder import CHUNK_RE, CHUNKS, DATASET, STATIC, list_chunks
from tactile.errors import DataError


def repair_hint(path: Path) -> str:
    """How to get a damaged ``dataset.h5`` or chunk file back (the ``Fix:`` of a read error)."""
    path = Path(path)
    if path.parent.name == CHUNKS and (CHUNK_RE.match(path.name) or path.name == STATIC):
        folder = path.parent.parent
        return (
            f"Fix: delete {path} and rerun the same handskin generate --out {folder}: it "
            "recomputes that chunk, then merges"
        )
    folder = path.parent
    if path.name == DATASET and list_chunks(folder) and (folder / CHUNKS / STATIC).is_file():
        return f"Fix: rebuild it from its chunks: handskin merge {folder} --out {folder}"
    return (
        f"Fix: regenerate it (its configuration is in {folder / 'manifest.json'}) or restore a "
        "copy; handskin verify lists every damaged sample"
    )


def bad_rows(ds: h5py.Dataset, key: object) -> tuple[int, int] | None:
    """(first, last) sample of the first HDF5 chunk selected by ``key`` that fails to read, or
    None when each reads on its own."""
    n = len(ds) if ds.shape else 0
    first = key[0] if isinstance(key, tuple) and key else key
    if isinstance(first, int | np.integer):
        rows = np.array([int(first) % max(n, 1)])
    elif isinstance(first, slice | list | np.ndarray):
        rows = np.arange(n)[first]
    else:
        rows = np.arange(n)
    step = ds.chunks[0] if ds.chunks else max(n, 1)
    for start in np.unique(np.asarray(rows, dtype=np.int64).ravel() // step * step):
        try:
            ds[int(start) : int(start) + step]
        except OSError:
            return int(start), min(int(start) + step, n) - 1
    return None


def read_error(ds: h5py.Dataset, field: str, path: Path, key: object = ()) -> DataError:
    """The DataError of a failed read of ``field`` (``ds``, selection ``key``) in ``path``."""
    rows = bad_rows(ds, key)
    if rows is None:
        where = "cannot be read"
    elif rows[0] == rows[1]:
        where = f"of sample {rows[0]} cannot be read"
    else:
        where = f"of samples {rows[0]}..{rows[1]} (one HDF5 chunk) cannot be read"
    why = "checksum mismatch or damaged compressed data"
    why = why if ds.fletcher32 else "damaged compressed data; this older file has no checksums"
    return DataError(f"{path}: field {field!r} {where} ({why}). {repair_hint(path)}")


class FieldView:
    """An h5py.Dataset of one field read like the dataset itself (``[i]``, ``[a:b]``, ``[()]``,
    ``.shape``, ``.asstr()``), whose failed reads raise `read_error`'s DataError."""

    def __init__(self, ds: h5py.Dataset, field: str, path: Path, as_str: bool = False) -> None:
        self._ds, self._field, self._path, self._as_str = ds, field, Path(path), as_str

    def __getitem__(self, key):
        try:
            return self._ds.asstr()[key] if self._as_str else self._ds[key]
        except OSError:
            raise read_error(self._ds, self._field, self._path, key) from None

    def asstr(self) -> FieldView:
        return FieldView(self._ds, self._field, self._path, as_str=True)

    def __len__(self) -> int:
        return len(self._ds)

    def __array__(self, dtype=None, copy=None):
        arr = self[()]
        return arr if dtype is None else arr.astype(dtype)

    def __getattr__(self, name: str):
        return getattr(self._ds, name)

    def __repr__(self) -> str:
        return f"FieldView({self._field!r}, shape={self._ds.shape}, file={str(self._path)!r})"


def open_h5(path: Path) -> h5py.File:
    """``path`` opened read-only; a file HDF5 cannot open is a DataError with `repair_hint`."""
    try:
        return h5py.File(path, "r")
    except OSError as err:
        raise DataError(
            f"{path}: not a readable HDF5 file ({str(err).splitlines()[0]}). {repair_hint(path)}"
        ) from None


def read_or_name(ds: h5py.Dataset, field: str, path: Path, key: object = ()) -> np.ndarray:
    """``ds[key]`` (strings decoded), a failed read named by `read_error`."""
    return FieldView(ds, field, path, as_str=h5py.check_string_dtype(ds.dtype) is not None)[key]
