"""Reproducible HDF5 building blocks: files, groups and datasets without timestamps, JSON attrs,
atomic writes, and the tactile map + layout stored as plain arrays.

HDF5 stamps every object header with its creation time unless told otherwise; root group, groups
and datasets are all created here with time tracking off, so the same content written twice gives
the same bytes. Every numeric dataset carries a fletcher32 checksum per HDF5 chunk, so a damaged
byte fails its read instead of passing unseen. HDF5 writes through a Python file object
(`tactile.dataset.h5sink.SafeSink`) that never reports a failed write to the library (h5py
crashes when a file cannot be written): a full disk surfaces once, afterwards, as an
``OSError`` naming the file.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np

from tactile.dataset.h5sink import SafeSink
from tactile.files import atomic_path
from tactile.geometry.distortion import DistortionReport
from tactile.geometry.layout import TaxelLayout
from tactile.images.tactile_map import TactileMap

GZIP_LEVEL = 4  # zlib level: ~the size of level 9 at a fraction of the time on sparse images
SCALAR_CHUNK = 1024  # samples per HDF5 chunk of a scalar field (one sample would waste space)
MAP_ARRAYS = ("positions_m", "uv", "vertex_uv_mm", "vertex_taxel", "faces")
DISTORTION = ("area_ratio", "angle_error_deg", "edge_ratio")
LAYOUT_ARRAYS = ("positions_m", "normals", "module_ids", "channel_ids", "merged_channels")


def canonical_json(obj: object) -> str:
    """JSON with sorted keys and fixed separators: equal objects give equal strings."""
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), ensure_ascii=False)


__all__ = ["atomic_path"]  # re-exported: `tactile.files.atomic_path`


def write_json(path: Path, obj: object) -> None:
    """Write indented, key-sorted JSON atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(obj, sort_keys=True, indent=2) + "\n", encoding="utf-8")


def create_file(path: Path) -> h5py.File:
    """A new (truncated) HDF5 file whose root group carries no timestamps."""
    fcpl = h5py.h5p.create(h5py.h5p.FILE_CREATE)
    fcpl.set_obj_track_times(False)
    return h5py.File(h5py.h5f.create(os.fsencode(path), h5py.h5f.ACC_TRUNC, fcpl=fcpl))


_SINKS: dict[int, SafeSink] = {}  # id of an open h5py FileID -> its sink


def check_written(f: h5py.File) -> None:
    """Raise the OSError (naming the file) of a write that failed so far into ``f``, if one did;
    long writers call it between steps to stop early."""
    sink = _SINKS.get(id(f.id))
    if sink is not None and sink.error is not None:
        raise sink.error


def _create_safe(fh, path: Path) -> tuple[h5py.File, SafeSink]:
    sink = SafeSink(fh)
    fcpl = h5py.h5p.create(h5py.h5p.FILE_CREATE)
    fcpl.set_obj_track_times(False)
    fapl = h5py.h5p.create(h5py.h5p.FILE_ACCESS)
    fapl.set_fileobj_driver(h5py.h5fd.fileobj_driver, sink)
    f = h5py.File(h5py.h5f.create(os.fsencode(path), h5py.h5f.ACC_TRUNC, fcpl=fcpl, fapl=fapl))
    _SINKS[id(f.id)] = sink
    return f, sink


def group(parent: h5py.Group, name: str) -> h5py.Group:
    """The subgroup ``name`` of ``parent``, created without timestamps when absent."""
    if name in parent:
        return parent[name]
    gcpl = h5py.h5p.create(h5py.h5p.GROUP_CREATE)
    gcpl.set_obj_track_times(False)
    h5py.h5g.create(parent.id, name.encode(), gcpl=gcpl)
    return parent[name]


def h5_dtype(dtype: str) -> np.dtype:
    """The HDF5 dtype of a schema dtype (``"str"`` = variable-length UTF-8)."""
    return h5py.string_dtype("utf-8") if dtype == "str" else np.dtype(dtype)


def filters(dtype: str, level: int = GZIP_LEVEL) -> dict[str, object]:
    """HDF5 filters of a per-sample field: gzip + shuffle + fletcher32 for numbers; none for
    variable-length strings (HDF5 filters only their heap references)."""
    if dtype == "str":
        return {}
    return {"compression": "gzip", "compression_opts": level, "shuffle": True, "fletcher32": True}


def stacked_dataset(
    parent: h5py.Group, name: str, n: int, shape: tuple[int, ...], dtype: str
) -> h5py.Dataset:
    """An (n, *shape) dataset chunked one sample per chunk (scalars: SCALAR_CHUNK per chunk),
    `filters`, no timestamps."""
    chunks = (1, *shape) if shape else (max(1, min(n, SCALAR_CHUNK)),)
    return parent.create_dataset(
        name,
        shape=(n, *shape),
        dtype=h5_dtype(dtype),
        chunks=chunks,
        track_times=False,
        **filters(dtype),
    )


def plain_dataset(parent: h5py.Group, name: str, data: np.ndarray) -> h5py.Dataset:
    """A small dataset (map arrays, split indices) in one HDF5 chunk with a fletcher32
    checksum (contiguous when empty), no timestamps."""
    data = np.asarray(data)
    kw = {"chunks": data.shape, "fletcher32": True} if data.size and data.ndim else {}
    return parent.create_dataset(name, data=data, track_times=False, **kw)


def set_attrs(obj: h5py.HLObject, attrs: dict[str, object]) -> None:
    """Set attributes in sorted key order: str, numbers and numeric arrays as they are; dicts,
    lists, booleans and None as canonical JSON text."""
    for key in sorted(attrs):
        value = attrs[key]
        native = isinstance(value, str | np.ndarray | np.number) or (
            isinstance(value, int | float) and not isinstance(value, bool)
        )
        obj.attrs[key] = value if native else canonical_json(value)


def write_map(parent: h5py.Group, tmap: TactileMap, layout: TaxelLayout) -> None:
    """Store the map (the arrays of ``TactileMap.save``) in ``/map`` and the layout in
    ``/map/layout``."""
    g = group(parent, "map")
    for key in MAP_ARRAYS:
        plain_dataset(g, key, getattr(tmap, key))
    for key in DISTORTION:
        plain_dataset(g, f"distortion_{key}", getattr(tmap.distortion, key))
    flipped = tmap.distortion.n_flipped
    set_attrs(g, {"step_mm": float(tmap.step_mm), "distortion_n_flipped": flipped})
    lg = group(g, "layout")
    for key in LAYOUT_ARRAYS:
        if getattr(layout, key) is not None:
            plain_dataset(lg, key, getattr(layout, key))
    n_ch = -1 if layout.n_channels is None else int(layout.n_channels)
    set_attrs(lg, {"name": layout.name, "n_channels": n_ch})


def read_map(g: h5py.Group) -> TactileMap:
    """The TactileMap stored by :func:`write_map` (look-up table rebuilt)."""
    report = DistortionReport(
        *(g[f"distortion_{k}"][()] for k in DISTORTION), int(g.attrs["distortion_n_flipped"])
    )
    return TactileMap.from_flat(
        g["positions_m"][()],
        g["vertex_uv_mm"][()],
        g["vertex_taxel"][()],
        g["faces"][()],
        step_mm=float(g.attrs["step_mm"]),
        distortion=report,
        taxel_uv_mm=g["uv"][()],
    )


def read_layout(g: h5py.Group) -> TaxelLayout:
    """The TaxelLayout stored by :func:`write_map` (``g`` is ``/map/layout``)."""
    arrays = {k: g[k][()] for k in LAYOUT_ARRAYS if k in g}
    n_ch = int(g.attrs["n_channels"])
    return TaxelLayout(**arrays, n_channels=None if n_ch < 0 else n_ch, name=str(g.attrs["name"]))


def json_attr(obj: h5py.HLObject, key: str) -> object:
    """A JSON attribute decoded."""
    return json.loads(obj.attrs[key])


def copy_tree(src: h5py.Group, dst: h5py.Group) -> None:
    """Copy groups, small datasets and attrs from ``src`` into ``dst`` (no timestamps)."""
    set_attrs(dst, dict(src.attrs))
    for key in src:
        item = src[key]
        if isinstance(item, h5py.Group):
            copy_tree(item, group(dst, key))
        else:
            plain_dataset(dst, key, item[()])


def write_h5(path: Path, fill: Callable[[h5py.File], None]) -> None:
    """Create ``path`` atomically: ``fill`` writes into a reproducible temporary file (through a
    `SafeSink`). A failed write (full disk) raises its OSError, with ``path`` as its filename,
    after the file is closed; the temporary file is removed and ``path`` left as it was."""
    with atomic_path(path) as tmp, open(tmp, "r+b", buffering=0) as fh:
        f, sink = _create_safe(fh, tmp)
        try:
            with f:
                fill(f)
        except Exception:
            if sink.error is None:
                raise
        finally:
            _SINKS.pop(id(f.id), None)
        if sink.error is not None:
            err = sink.error
            raise OSError(err.errno, err.strerror, str(path)) from err
