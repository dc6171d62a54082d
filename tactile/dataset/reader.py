"""Read a dataset lazily with h5py (no torch, no mujoco).

    ds = open_dataset("out/")            # the folder or its dataset.h5
    len(ds), ds[0]["image"], ds.raw[10:20], ds["is_hand"][:], ds.splits["train"], ds.map

The HDF5 file is opened on first access and reopened in a new process, so a reader can be
pickled into DataLoader workers (each worker opens its own handle).
"""

from __future__ import annotations

import json
import os
from functools import cached_property
from pathlib import Path

import h5py
import numpy as np

import tactile.dataset.h5io as h5io
from tactile.dataset.damage import FieldView, repair_hint
from tactile.dataset.folder import DATASET, INFO
from tactile.dataset.readout import Readout
from tactile.dataset.schema import BY_NAME, FIELDS, STR
from tactile.errors import DataError
from tactile.geometry.layout import TaxelLayout
from tactile.images.tactile_map import TactileMap

JSON_ATTRS = frozenset({"config", "versions", "class_balance", "rejects", "split_report"})


def decode_attr(key: str, value: object) -> object:
    """An attribute as Python: JSON text (dicts, lists, known JSON attrs) decoded, numpy scalars
    to Python numbers, arrays kept."""
    if isinstance(value, bytes):
        value = value.decode("utf-8")
    if isinstance(value, str) and (key in JSON_ATTRS or value[:1] in "[{"):
        return json.loads(value)
    if isinstance(value, np.generic):
        return value.item()
    return value


class DatasetReader:
    """Lazy, picklable view of one ``dataset.h5``.

    ``len(ds)``: samples S. ``ds[i]``: dict {field: value} of sample i (arrays; str for STR
    fields). ``ds["raw"]`` or ``ds.raw``: the field's h5py.Dataset, (S, ...) (sliced lazily;
    a damaged sample raises DataError naming file, field and sample). ``fields``: names
    present. ``map``, ``layout``, ``splits``, ``info``, ``attrs``, ``active_threshold_pa``: see
    below.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        path = Path(path)
        self.path = path / DATASET if path.is_dir() else path
        if not self.path.is_file():
            raise DataError(
                f"no dataset at {self.path}. Fix: give a dataset folder holding {DATASET} "
                "(merge the chunks first if only chunks/ exists)"
            )
        self._file: h5py.File | None = None
        self._pid = -1
        try:
            f = h5py.File(self.path, "r")
        except OSError as err:
            msg = f"cannot open {self.path} as HDF5 ({err}). Fix: re-run the merge"
            raise DataError(msg) from err
        with f:
            if "samples" not in f or "raw" not in f["samples"] or "map" not in f:
                raise DataError(f"{self.path} is not a handskin dataset (no /samples/raw or /map)")
            self.fields = tuple(s.name for s in FIELDS if s.path in f)
            self._len = int(f["samples/raw"].shape[0])

    @property
    def file(self) -> h5py.File:
        """The open h5py.File (opened on first use, reopened in a forked/spawned worker)."""
        if self._file is None or self._pid != os.getpid():
            self._file = h5py.File(self.path, "r")
            self._pid = os.getpid()
        return self._file

    def close(self) -> None:
        """Close the file handle (it reopens on the next access)."""
        if self._file is not None and self._pid == os.getpid():
            self._file.close()
        self._file = None

    def __enter__(self) -> DatasetReader:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def __getstate__(self) -> dict:
        state = self.__dict__.copy()
        state["_file"], state["_pid"] = None, -1
        for key in ("map", "layout"):  # rebuilt lazily in the new process
            state.pop(key, None)
        return state

    def __len__(self) -> int:
        return self._len

    def __repr__(self) -> str:
        return f"DatasetReader({str(self.path)!r}, {self._len} samples, fields={self.fields})"

    def __getitem__(self, key: int | str) -> dict[str, object] | FieldView:
        if isinstance(key, str):
            if key not in self.fields:
                raise KeyError(f"no field {key!r} in {self.path}; fields: {', '.join(self.fields)}")
            return self._field(key)
        i = int(key)
        if not -self._len <= i < self._len:
            raise IndexError(f"sample {i} out of range for {self._len} samples")
        return {name: self.sample_field(name, i % self._len) for name in self.fields}

    def __getattr__(self, name: str) -> FieldView:
        if name.startswith("_") or name not in self.__dict__.get("fields", ()):
            raise AttributeError(name)
        return self._field(name)

    def _field(self, name: str) -> FieldView:
        return FieldView(self.file[BY_NAME[name].path], name, self.path)

    def sample_field(self, name: str, i: int) -> object:
        """One field of sample i: an array, a numpy scalar, or str for STR fields."""
        view = self._field(name)
        return view.asstr()[i] if BY_NAME[name].dtype == STR else view[i]

    def _whole(self, read, what: str):
        """``read()`` of a group that is not per sample; a damaged array is named."""
        try:
            return read()
        except OSError as err:
            raise DataError(
                f"{self.path}: {what} cannot be read (checksum mismatch or damaged data: "
                f"{str(err).splitlines()[0]}). {repair_hint(self.path)}"
            ) from None

    @cached_property
    def map(self) -> TactileMap:
        """The dataset's TactileMap, rebuilt from ``/map`` (same look-up table as at writing)."""
        return self._whole(lambda: h5io.read_map(self.file["map"]), "the tactile map (/map)")

    @cached_property
    def layout(self) -> TaxelLayout:
        """The part's TaxelLayout from ``/map/layout``."""
        read = lambda: h5io.read_layout(self.file["map/layout"])  # noqa: E731
        return self._whole(read, "the taxel layout (/map/layout)")

    @property
    def splits(self) -> dict[str, np.ndarray]:
        """{"train": (K,) int64, "test": (K',) int64} sample indices."""
        read = lambda: {k: v[()] for k, v in self.file["splits"].items()}  # noqa: E731
        return self._whole(read, "the train/test split (/splits)")

    @property
    def attrs(self) -> dict[str, object]:
        """Root attributes, JSON ones decoded (config, versions, class_balance, rejects, ...)."""
        return {k: decode_attr(k, v) for k, v in self.file.attrs.items()}

    @property
    def active_threshold_pa(self) -> float:
        """The pressure (Pa) above which this dataset's taxels are labelled active: its generation
        config's ``episode.active_pa``; 0.0 when not recorded (e.g. an ingested recording)."""
        config = self.attrs.get("config")
        episode = config.get("episode") if isinstance(config, dict) else None
        value = episode.get("active_pa", 0.0) if isinstance(episode, dict) else 0.0
        is_number = isinstance(value, int | float) and not isinstance(value, bool)
        return float(value) if is_number else 0.0

    @property
    def info(self) -> dict:
        """The sidecar ``info.json`` (fields with dtype, shape, unit; counts; splits)."""
        path = self.path.with_name(INFO)
        try:
            return json.loads(path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as err:
            raise DataError(f"cannot read {path}: {err}. Fix: re-run the merge") from err

    @cached_property
    def readout(self) -> Readout:
        """How this dataset's raw counts become pressures (`tactile.dataset.readout`)."""
        return Readout.of(self.attrs)

    def pressure_from_raw(
        self, raw: np.ndarray, time_s: np.ndarray | float | None = None
    ) -> np.ndarray:
        """Pressure from raw readings, as the generator imaged them: ``raw - baseline - drift *
        time_s``, signals at or below the noise floor read 0, over the nominal gain.

        raw : (N,) or (B, N) counts. time_s : the frames' times (scalar or (B,), s; the field
        ``time_s``); None removes no drift. Returns the shape of ``raw``, float64, Pa. The root
        attrs that say how are listed in `tactile.dataset.readout`; per-taxel gain spread is not
        undone (a robot does not know it).
        """
        return self.readout.pressure_pa(raw, time_s)

    def images_from_raw(
        self,
        raw: np.ndarray,
        tmap: TactileMap | None = None,
        keep: np.ndarray | None = None,
        time_s: np.ndarray | float | None = None,
    ) -> np.ndarray:
        """Tactile images recomputed from raw readings through a (possibly corrupted) map.

        raw : (N,) or (B, N) counts. tmap : the map to use (default: the dataset's). keep :
        (K,) taxel indices when ``tmap`` was built from ``layout.subset(keep)``. time_s : as in
        `pressure_from_raw`. Returns (H, W) or (B, H, W) uint8 with (H, W) = tmap.shape.
        """
        p = self.pressure_from_raw(raw, time_s)
        if keep is not None:
            p = p[..., np.asarray(keep)]
        return (self.map if tmap is None else tmap).image(p)


def open_dataset(path: str | os.PathLike[str]) -> DatasetReader:
    """Open a dataset folder (or its ``dataset.h5``) lazily; DataError when there is none."""
    return DatasetReader(path)
