"""Write a dataset folder: manifest first, samples in atomic chunks (resumable), one merge.

    writer = DatasetWriter(out, config=cfg, part="forearm", generator_version="1", seed=7,
                           tmap=tmap, layout=layout, attrs={"skin_counts_per_pa": 0.05, ...})
    for k in range(n_chunks):
        if k not in writer.complete_chunks():
            writer.write_chunk(k, [make_sample(i) for i in chunk_samples(k)], rejects={...})
    writer.merge()                       # -> out/dataset.h5 and out/info.json

A sample is a dict {field name: array} (see :mod:`tactile.dataset.schema`). A chunk is written to
a temporary file in ``chunks/`` and renamed to ``chunk_{k:06d}.h5`` only when complete, so after a
kill only complete chunks carry that name. The merge streams chunk by chunk (memory of one chunk)
into ``dataset.h5`` — built reproducibly, so the same chunks give the same bytes.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import h5py
import numpy as np

import tactile.dataset.h5io as h5io
from tactile.dataset.folder import CHUNKS, STATIC, chunk_path, list_chunks
from tactile.dataset.manifest import claim_folder, jsonable, make_manifest
from tactile.dataset.merge import merge_chunks
from tactile.dataset.schema import BY_NAME, STR, Dims, validate_sample
from tactile.errors import DataError
from tactile.files import remove_stale
from tactile.geometry.layout import TaxelLayout
from tactile.images.tactile_map import TactileMap

RESERVED_ATTRS = frozenset(
    {
        "format",
        "fingerprint",
        "config",
        "versions",
        "generator_version",
        "seed",
        "part",
        "class_balance",
        "rejects",
        "split_method",
        "split_report",
        "train_fraction",
        "n_samples",
    }
)


def _check_attrs(attrs: Mapping[str, object]) -> dict[str, object]:
    clash = sorted(RESERVED_ATTRS & set(attrs))
    if clash:
        raise DataError(f"attrs {clash} are reserved (set by the writer). Fix: rename them")
    out: dict[str, object] = {}
    for key, value in attrs.items():
        is_array = isinstance(value, np.ndarray) and value.dtype.kind in "iuf"
        out[str(key)] = value if is_array else jsonable(value)
    return out


class DatasetWriter:
    """Writer of one dataset folder (see the module docstring).

    Parameters
    ----------
    out_dir : the dataset folder; created, resumed (same fingerprint) or refused (DataError).
    config : resolved configuration (dataclass or JSON-ready dict). part : str, skin part name.
    generator_version : str. seed : int, the dataset seed (also seeds the train/test split).
    tmap, layout : the part's TactileMap and its TaxelLayout (N taxels, (H, W) images).
    attrs : extra root attributes, e.g. ``skin_counts_per_pa`` (float, counts/Pa),
        ``skin_baseline_counts`` (float or (N,) float, counts), ``actions`` (list of str).
    seq_len : T, frames of the optional ``seq_raw`` field.
    """

    def __init__(
        self,
        out_dir: str | Path,
        *,
        config: object,
        part: str,
        generator_version: str,
        seed: int,
        tmap: TactileMap,
        layout: TaxelLayout,
        attrs: Mapping[str, object] | None = None,
        seq_len: int | None = None,
    ) -> None:
        if tmap.n_taxels != layout.n_taxels:
            raise DataError(f"map has {tmap.n_taxels} taxels, layout {layout.n_taxels}")
        extra = _check_attrs(attrs or {})
        self.folder = Path(out_dir)
        self.manifest = make_manifest(config, part, generator_version, seed)
        self.dims = Dims(layout.n_taxels, *tmap.shape, seq_len)
        self.resumed = claim_folder(self.folder, self.manifest)
        (self.folder / CHUNKS).mkdir(exist_ok=True)
        self._remove_stale_temporaries()
        static = self.folder / CHUNKS / STATIC
        if not static.exists():
            h5io.write_h5(static, lambda f: self._static(f, tmap, layout, extra))

    def _static(self, f: h5py.File, tmap: TactileMap, layout: TaxelLayout, extra: dict) -> None:
        h5io.write_map(f, tmap, layout)
        h5io.set_attrs(f, extra)
        seq = -1 if self.dims.seq_len is None else self.dims.seq_len
        h5io.set_attrs(f["map"], {"dims": np.array([self.dims.n_taxels, *tmap.shape, seq])})

    def _remove_stale_temporaries(self) -> None:
        """Delete temporary files left by a killed run (never complete chunks)."""
        remove_stale(self.folder / CHUNKS)
        remove_stale(self.folder)

    def complete_chunks(self) -> list[int]:
        """Indices of the chunks already on disk (a resumed run skips them)."""
        return list_chunks(self.folder)

    def write_chunk(
        self, k: int, samples: Sequence[Mapping[str, object]], *, rejects: Mapping | None = None
    ) -> Path:
        """Validate ``samples`` then write them atomically as chunk ``k``; return its path.

        samples : dicts {field: value}, all with the same fields (those of earlier chunks).
        rejects : {reason: count} of episodes rejected while producing this chunk.
        """
        if isinstance(k, bool) or not isinstance(k, int | np.integer) or not 0 <= k < 10**6:
            raise DataError(f"chunk index must be an int in 0..999999, got {k!r}")
        if not samples:
            raise DataError(f"chunk {k} has no samples. Fix: pass at least one sample")
        fields = self._fields_on_disk()
        checked = []
        for j, sample in enumerate(samples):
            try:
                checked.append(validate_sample(sample, self.dims, fields))
            except DataError as err:
                raise DataError(f"chunk {k}, sample {j}: {err}") from None
            fields = fields or tuple(checked[0])
        counts = {str(r): int(n) for r, n in (rejects or {}).items()}
        if any(n < 0 for n in counts.values()):
            raise DataError(f"chunk {k}: reject counts must be >= 0, got {counts}")
        path = chunk_path(self.folder, k)
        h5io.write_h5(path, lambda f: _fill_chunk(f, k, fields, checked, counts))
        return path

    def _fields_on_disk(self) -> tuple[str, ...] | None:
        done = self.complete_chunks()
        if not done:
            return None
        with h5py.File(chunk_path(self.folder, done[0]), "r") as f:
            return tuple(h5io.json_attr(f, "fields"))

    def merge(
        self,
        *,
        n_chunks: int | None = None,
        train_fraction: float = 0.7,
        remove_chunks: bool = False,
    ) -> Path:
        """Merge the chunks into ``dataset.h5`` (see :func:`tactile.dataset.merge.merge_chunks`)."""
        return merge_chunks(
            self.folder,
            n_chunks=n_chunks,
            train_fraction=train_fraction,
            remove_chunks=remove_chunks,
        )


def _fill_chunk(
    f: h5py.File, k: int, fields: Sequence[str], samples: list[dict], rejects: dict
) -> None:
    for name in fields:
        spec = BY_NAME[name]
        parent, leaf = spec.path.split("/")
        values = [s[name] for s in samples]
        data = np.array(values, dtype=object) if spec.dtype == STR else np.stack(values)
        kw = h5io.filters(spec.dtype)  # the merged file's: the merge copies the chunks as stored
        if kw and data.ndim > 1:
            kw["chunks"] = (1, *data.shape[1:])  # one sample per HDF5 chunk: damage is named
        h5io.group(f, parent).create_dataset(
            leaf, data=data, dtype=h5io.h5_dtype(spec.dtype), track_times=False, **kw
        )
    h5io.set_attrs(
        f, {"chunk": int(k), "n_samples": len(samples), "fields": list(fields), "rejects": rejects}
    )
