"""The dataset's fields in one table, and validation of one sample dict against it.

A *sample* is a dict ``{field name: value}`` for one accepted episode, as produced by the
simulation (``sim/generate/run.py``) or by :mod:`tactile.dataset.ingest`. Shapes are templates over
the dataset's dimensions: N taxels, (H, W) map pixels, T sequence frames (see :class:`Dims`).
Every dataset holds ``raw``, ``pressure_pa`` and ``image``; the other fields are optional, but
all samples of one dataset carry the same set. Field names are the sample-dict keys; ``path`` is
where a field lives in ``dataset.h5`` (fixed-size samples stacked on axis 0).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from tactile.errors import DataError
from tactile.images.labels import N_CLASSES

STR = "str"  # dtype marker of variable-length UTF-8 strings (h5py.string_dtype())
MAX_CONTACTS = 2  # contactors pressing at once in one sample


@dataclass(frozen=True)
class FieldSpec:
    """One field: sample-dict key, HDF5 path, dtype, per-sample shape template, unit, meaning.

    shape : tuple of "N" (taxels), "H", "W" (map pixels), "T" (sequence frames) or ints; () for a
    scalar. values : inclusive (low, high) of allowed values, or None for the dtype's range.
    """

    name: str
    path: str
    dtype: str
    shape: tuple[str | int, ...]
    unit: str
    description: str
    required: bool = False
    values: tuple[int, int] | None = None


def _s(name: str, dtype: str, shape: tuple, unit: str, text: str, **kw: object) -> FieldSpec:
    return FieldSpec(name, f"samples/{name}", dtype, shape, unit, text, **kw)


LABELS = (0, N_CLASSES - 1)
FIELDS: tuple[FieldSpec, ...] = (
    _s("raw", "uint16", ("N",), "count", "16-bit skin reading per taxel (noisy)", required=True),
    _s(
        "pressure_pa",
        "float32",
        ("N",),
        "Pa",
        "noise-free pressure per taxel (ingest: (raw - baseline) / counts_per_pa, clipped at 0)",
        required=True,
    ),
    _s(
        "taxel_label",
        "uint8",
        ("N",),
        "class",
        "class per taxel: 0 none, 1..6 hand parts (tactile.CLASS_NAMES)",
        values=LABELS,
    ),
    _s(
        "taxel_contactor",
        "int16",
        ("N",),
        "index",
        "index into the sample's contactor list, -1 none",
        values=(-1, 32767),
    ),
    _s(
        "image",
        "uint8",
        ("H", "W"),
        "grey level",
        "tactile image from the readings (paper's pipeline, TactileMap.image)",
        required=True,
    ),
    _s(
        "label_image",
        "uint8",
        ("H", "W"),
        "class",
        "class per pixel (0 for non-hand samples)",
        values=LABELS,
    ),
    _s(
        "instance_image",
        "uint8",
        ("H", "W"),
        "contact",
        "contact per pixel: 0 none, k + 1 for contact k (datasets with several contacts)",
        values=(0, MAX_CONTACTS),
    ),
    _s("is_hand", "uint8", (), "bool", "1 hand (among the contacts), 0 non-hand", values=(0, 1)),
    _s(
        "n_contacts",
        "uint8",
        (),
        "count",
        "contactors pressing in the sample (datasets with several contacts)",
        values=(1, MAX_CONTACTS),
    ),
    _s(
        "contact_subject",
        "int32",
        (MAX_CONTACTS,),
        "id",
        "person of each contact, -1 for none or a non-hand (datasets with several contacts)",
    ),
    _s(
        "contact_instance",
        "int32",
        (MAX_CONTACTS,),
        "id",
        "object / body-part instance of each contact, -1 for none or a hand",
    ),
    _s("action", "int8", (), "index", "index into attrs['actions'], -1 none", values=(-1, 127)),
    _s(
        "operator_position", "int8", (), "index", "0 front, 1 side, 2 free, -1 none", values=(-1, 2)
    ),
    _s("subject_id", "int32", (), "id", "subject of a hand sample, -1 for non-hand samples"),
    _s("instance_id", "int32", (), "id", "object / body-part instance, -1 for hand samples"),
    _s("contactor", STR, (), "JSON", "JSON description of the contactor(s)"),
    _s("episode_seed", "uint64", (), "seed", "seed of the accepted episode"),
    _s("force_n", "float32", (), "N", "total normal force at the sampled frame"),
    _s("time_s", "float32", (), "s", "time of the sampled frame in the episode"),
    FieldSpec(
        "seq_raw",
        "sequences/raw",
        "uint16",
        ("T", "N"),
        "count",
        "10 Hz sequence of raw readings, zero-padded after seq_length frames",
    ),
    FieldSpec(
        "seq_length",
        "sequences/length",
        "int16",
        (),
        "frames",
        "valid frames of seq_raw",
        values=(0, 32767),
    ),
    FieldSpec(
        "seq_phase_s",
        "sequences/phase_s",
        "float32",
        (4,),
        "s",
        "end times of the approach, load, hold and release; frame k is read at 0.1 (k + 1) s",
    ),
)
BY_NAME: dict[str, FieldSpec] = {f.name: f for f in FIELDS}
REQUIRED = tuple(f.name for f in FIELDS if f.required)


@dataclass(frozen=True)
class Dims:
    """Dataset dimensions: N taxels, (H, W) map pixels, T sequence frames (None: no sequences)."""

    n_taxels: int
    height: int
    width: int
    seq_len: int | None = None

    def resolve(self, spec: FieldSpec) -> tuple[int, ...]:
        """The concrete per-sample shape of ``spec``; DataError when T is needed but unknown."""
        table = {"N": self.n_taxels, "H": self.height, "W": self.width, "T": self.seq_len}
        out = tuple(table[s] if isinstance(s, str) else s for s in spec.shape)
        if None in out:
            raise DataError(
                f"field {spec.name!r} needs the sequence length T, unknown here. "
                "Fix: pass Dims(..., seq_len=T) to the writer"
            )
        return out  # type: ignore[return-value]


def field_spec(name: str) -> FieldSpec:
    """The spec of ``name``; DataError listing the known fields otherwise."""
    if name not in BY_NAME:
        raise DataError(f"unknown field {name!r}; known fields: {', '.join(BY_NAME)}")
    return BY_NAME[name]


def check_field_set(names: object, where: str = "sample") -> tuple[str, ...]:
    """The names in schema order; DataError for unknown or missing required fields."""
    names = set(names)  # type: ignore[arg-type]
    for name in sorted(names):
        field_spec(name)
    missing = [r for r in REQUIRED if r not in names]
    if missing:
        raise DataError(f"{where} lacks required field(s) {missing}. Fix: add them")
    return tuple(f.name for f in FIELDS if f.name in names)


def validate_sample(
    sample: Mapping[str, object], dims: Dims, fields: tuple[str, ...] | None = None
) -> dict[str, object]:
    """Check a sample against the schema; return it with values cast to the field dtypes.

    ``fields``: the dataset's field set (all samples must match it); default: the sample's own.
    Arrays are accepted when their kind fits and every value is representable (e.g. int64 0..65535
    for uint16); NaN/inf in float fields, out-of-range values, wrong shapes and missing or extra
    fields raise DataError naming the field, the expected and the received dtype/shape.
    """
    names = check_field_set(sample.keys())
    if fields is not None and names != tuple(fields):
        extra, missing = set(names) - set(fields), set(fields) - set(names)
        raise DataError(
            f"sample fields differ from the dataset's: extra {sorted(extra)}, missing "
            f"{sorted(missing)}. Fix: give every sample the same fields"
        )
    return {n: check_value(BY_NAME[n], sample[n], dims) for n in names}


def check_value(spec: FieldSpec, value: object, dims: Dims) -> object:
    """One field's value cast to its dtype (str for STR fields), or DataError."""
    if spec.dtype == STR:
        if isinstance(value, bytes):
            value = value.decode("utf-8")
        if not isinstance(value, str):
            raise DataError(f"field {spec.name!r}: expected a str, got {type(value).__name__}")
        return value
    arr = np.asarray(value)
    want = dims.resolve(spec)
    if arr.shape != want:
        raise DataError(
            f"field {spec.name!r}: expected shape {want} ({spec.dtype}), got {arr.shape} "
            f"({arr.dtype})"
        )
    return _cast(spec, arr)


def _cast(spec: FieldSpec, arr: np.ndarray) -> np.ndarray:
    target = np.dtype(spec.dtype)
    got = f"got {arr.dtype} with shape {arr.shape}"
    if target.kind == "f":
        if arr.dtype.kind not in "fiu":
            raise DataError(f"field {spec.name!r}: expected {target} ({spec.unit}), {got}")
        out = arr.astype(target)
        if not np.isfinite(out).all():
            at = tuple(int(i) for i in np.argwhere(~np.isfinite(out))[0])
            raise DataError(
                f"field {spec.name!r}: NaN or inf (after cast to {target}) at index {at}. "
                "Fix: reject or repair the sample before writing"
            )
        return out
    if arr.dtype.kind not in "iub":
        raise DataError(f"field {spec.name!r}: expected {target} ({spec.unit}), {got}")
    low, high = spec.values or (np.iinfo(target).min, np.iinfo(target).max)
    if arr.size and (arr.min() < low or arr.max() > high):
        raise DataError(
            f"field {spec.name!r}: values must lie in {low}..{high} ({target}, {spec.unit}); "
            f"{got}, range {arr.min()}..{arr.max()}"
        )
    return arr.astype(target)


def info_fields(fields: tuple[str, ...], dims: Dims) -> dict[str, dict[str, object]]:
    """info.json's field table: path, dtype, per-sample shape, unit, description."""
    return {
        n: {
            "path": BY_NAME[n].path,
            "dtype": BY_NAME[n].dtype,
            "shape": list(dims.resolve(BY_NAME[n])),
            "unit": BY_NAME[n].unit,
            "description": BY_NAME[n].description,
        }
        for n in fields
    }
