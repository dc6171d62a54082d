"""`verify_dataset`: a dataset checked end to end, every fault named with its fix.

    report = verify_dataset("out/forearm")      # Report: ok lines, faults, notes
    report.faults   # ["dataset.h5: field 'image' of sample 5 cannot be read (checksum ...", ...]

Checks, in order: the manifest's fingerprint and content hash of ``dataset.h5`` and ``info.json``
(each JSON value's shape first, `tactile.dataset.sidecars`); the fields (schema dtypes, shapes
over N, H, W, T); every field of every sample read (HDF5 fletcher32 checksums and gzip
streams) with label ranges and finite floats; the map and layout; the
train/test split (indices in range, disjoint, covering every sample, no subject or instance on
both sides); ``info.json`` and the root attributes; the files in ``chunks/`` when still there. A
run not merged yet: its manifest, and its chunks against those its configuration writes.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import h5py
import numpy as np
from tqdm import tqdm

import tactile.dataset.h5io as h5io
from tactile.dataset.damage import bad_rows, open_h5, read_error, repair_hint
from tactile.dataset.folder import CHUNKS, DATASET, INFO, STATIC, list_chunks
from tactile.dataset.manifest import CONTENT, FORMAT, MANIFEST, file_digest, read_manifest
from tactile.dataset.schema import BY_NAME, FIELDS, REQUIRED, STR, Dims
from tactile.dataset.sidecars import digest_fault, fingerprint_faults, json_kind, run_chunk_faults
from tactile.errors import DataError

MAX_LISTED = 10  # damaged samples listed per field; the rest counted


@dataclass
class Report:
    """What `verify_dataset` found: ``ok`` (checks passed), ``faults``, ``notes``."""

    path: Path
    ok: list[str] = field(default_factory=list)
    faults: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)

    def check(self, faults: list[str], passed: str) -> None:
        """Record ``faults``, or ``passed`` when there are none."""
        self.faults += faults
        if not faults:
            self.ok.append(passed)


def dataset_file(path: Path) -> Path:
    """The ``dataset.h5`` of a folder (or the file itself); DataError when there is none."""
    path = Path(path)
    file = path / DATASET if path.is_dir() else path
    if not file.is_file():
        raise DataError(f"no dataset at {path}. Fix: give a folder holding {DATASET}")
    return file


def verify_dataset(path: str | Path, progress: bool = False) -> Report:
    """Check the dataset at ``path`` (folder or ``dataset.h5``); see the module docstring. A
    folder with chunks but no ``dataset.h5`` yet (a run not merged) has its chunks checked."""
    path = Path(path)
    if path.is_dir() and not (path / DATASET).exists() and list_chunks(path):
        report = Report(path / DATASET, notes=[f"no {DATASET} yet (not merged): chunks only"])
        _run(path, report)
        _chunks(path, report, progress)
        return report
    file = dataset_file(path)
    report = Report(file)
    _content(file, report)
    try:
        f = open_h5(file)
    except DataError as err:
        report.faults.append(str(err))
        return report
    with f:
        if "samples/raw" not in f or "map" not in f:
            report.faults.append(f"{file}: not a handskin dataset (no /samples/raw or /map)")
            return report
        fields = [s.name for s in FIELDS if s.path in f]
        n = int(f["samples/raw"].shape[0])
        report.check(_shapes(f, fields, n), f"{len(fields)} fields of {n} samples, shapes agree")
        _checksums(f, report)
        faults = [m for name in fields for m in _read_all(f, name, file, progress)]
        report.check(faults, "every field of every sample reads (values in range)")
        report.check(_map(f, file), "map and layout read, map agrees with the images")
        report.check(_splits(f, file, n), "train/test split: disjoint, complete, groups apart")
        report.check(_info(f, file, fields, n), f"{INFO} and the root attributes agree")
    _chunks(file.parent, report, progress)
    return report


def _run(folder: Path, report: Report) -> None:
    """An unmerged run's manifest, and its chunks against those its configuration writes."""
    try:
        manifest = read_manifest(folder)
    except DataError as err:
        report.faults.append(str(err))
        return
    report.check(fingerprint_faults(folder, manifest), f"{MANIFEST}: fingerprint")
    faults, notes = run_chunk_faults(folder, manifest)
    report.notes += notes
    report.check(faults, f"{CHUNKS}/: the chunks of the run in {MANIFEST}")


def _content(file: Path, report: Report) -> None:
    """The manifest's digests of dataset.h5 and info.json against the files."""
    if not (file.parent / MANIFEST).is_file():
        report.notes.append(f"no {MANIFEST} beside {file.name}: its content hash is not checked")
        return
    try:
        manifest = read_manifest(file.parent)
    except DataError as err:
        report.faults.append(str(err))
        return
    report.check(fingerprint_faults(file.parent, manifest), f"{MANIFEST}: fingerprint")
    recorded = manifest.get(CONTENT)
    if recorded is None:
        report.notes.append(f"{MANIFEST} records no content hash (merged by an older handskin)")
        return
    where = f"{file.parent / MANIFEST}: content"
    if not isinstance(recorded, dict):
        report.faults.append(
            f"{where} is {json_kind(recorded)}, not an object. {repair_hint(file)}"
        )
        return
    faults = []
    for name, want in recorded.items():
        fault = digest_fault(want) if name in (DATASET, INFO) else "not a file of the dataset"
        if fault is not None:
            faults.append(f"{where} {name!r}: {fault}: the file was edited. {repair_hint(file)}")
            continue
        target = file.parent / name
        got = file_digest(target) if target.is_file() else None
        if got != want:
            have = "missing" if got is None else f"sha256 {got['sha256'][:12]}, {got['bytes']} B"
            faults.append(
                f"{target}: {have}, but its merge wrote sha256 {want.get('sha256', '?')[:12]}, "
                f"{want.get('bytes')} B ({MANIFEST}): the file changed since. "
                f"{repair_hint(file)}"
            )
    report.check(faults, f"content hash of {', '.join(recorded)} matches {MANIFEST}")


def _dims(f: h5py.File, n: int) -> Dims:
    d = [int(x) for x in f["map"].attrs.get("dims", [-1, -1, -1, -1])]
    return Dims(d[0], d[1], d[2], None if d[3] < 0 else d[3])


def _shapes(f: h5py.File, fields: list[str], n: int) -> list[str]:
    dims, out = _dims(f, n), []
    out += [f"{f.filename}: required field {r!r} missing" for r in REQUIRED if r not in fields]
    for name in fields:
        spec, ds = BY_NAME[name], f[BY_NAME[name].path]
        want_dtype = h5io.h5_dtype(spec.dtype)
        if spec.dtype != STR and ds.dtype != want_dtype:
            out.append(f"{f.filename}: field {name!r} is {ds.dtype}, the format says {want_dtype}")
        try:
            want = (n, *dims.resolve(spec))
        except DataError:
            want = (n, *ds.shape[1:])
        if ds.shape != want:
            out.append(f"{f.filename}: field {name!r} has shape {ds.shape}, expected {want}")
    return out


def _numeric(f: h5py.File) -> list[h5py.Dataset]:
    found: list[h5py.Dataset] = []
    f.visititems(lambda _, o: found.append(o) if isinstance(o, h5py.Dataset) else None)
    return [d for d in found if d.dtype.kind in "iufb" and d.size > 0 and d.ndim > 0]


def _checksums(f: h5py.File, report: Report) -> None:
    numeric = _numeric(f)
    missing = [d.name for d in numeric if not d.fletcher32]
    if missing:
        report.notes.append(
            f"{len(missing)} of {len(numeric)} arrays carry no HDF5 checksum (an older dataset): "
            "damage there is found only where it breaks decompression"
        )
    else:
        report.ok.append(f"HDF5 fletcher32 checksums on all {len(numeric)} arrays")


def _read_all(f: h5py.File, name: str, file: Path, progress: bool) -> list[str]:
    """Read field ``name`` HDF5 chunk by chunk; faults for damaged chunks and bad values."""
    spec, ds = BY_NAME[name], f[BY_NAME[name].path]
    step = ds.chunks[0] if ds.chunks else max(len(ds), 1)
    faults: list[str] = []
    bar = tqdm(range(0, len(ds), step), desc=name, unit="chunk", disable=not progress, leave=False)
    for start in bar:
        key = slice(start, start + step)
        try:
            values = ds.asstr()[key] if spec.dtype == STR else ds[key]
        except OSError:
            faults.append(str(read_error(ds, name, file, key)))
            continue
        faults += _values(spec, values, start, file)
    if len(faults) > MAX_LISTED:
        faults = [*faults[:MAX_LISTED], f"{file}: field {name!r}: {len(faults) - MAX_LISTED} more"]
    return faults


def _values(spec, values: np.ndarray, start: int, file: Path) -> list[str]:
    if spec.dtype == STR or not len(values):
        return []
    flat = values.reshape(len(values), -1)
    bad = ~np.isfinite(flat).all(1) if flat.dtype.kind == "f" else np.zeros(len(flat), bool)
    if spec.values is not None:
        bad |= (flat < spec.values[0]).any(1) | (flat > spec.values[1]).any(1)
    allowed = f"in {spec.values[0]}..{spec.values[1]}" if spec.values else "finite"
    return [
        f"{file}: field {spec.name!r} of sample {start + i}: values not {allowed}. "
        f"{repair_hint(file)}"
        for i in np.flatnonzero(bad)
    ]


def _map(f: h5py.File, file: Path) -> list[str]:
    try:
        tmap, layout = h5io.read_map(f["map"]), h5io.read_layout(f["map/layout"])
    except (OSError, KeyError, ValueError) as err:
        return [f"{file}: the map cannot be read ({str(err).splitlines()[0]}). {repair_hint(file)}"]
    out = []
    if tmap.n_taxels != f["samples/raw"].shape[1] or layout.n_taxels != tmap.n_taxels:
        out.append(
            f"{file}: map has {tmap.n_taxels} taxels, layout {layout.n_taxels}, raw "
            f"{f['samples/raw'].shape[1]}"
        )
    if tuple(f["samples/image"].shape[1:]) != tuple(tmap.shape):
        out.append(f"{file}: images are {f['samples/image'].shape[1:]}, the map {tmap.shape}")
    return out


def _splits(f: h5py.File, file: Path, n: int) -> list[str]:
    try:
        train, test = (np.asarray(f[f"splits/{k}"][()], np.int64) for k in ("train", "test"))
    except (OSError, KeyError) as err:
        return [
            f"{file}: the split cannot be read ({str(err).splitlines()[0]}). {repair_hint(file)}"
        ]
    both = np.concatenate([train, test])
    out = []
    if both.size and (both.min() < 0 or both.max() >= n):
        out.append(f"{file}: split indices outside 0..{n - 1}")
    if np.intersect1d(train, test).size:
        out.append(f"{file}: {np.intersect1d(train, test).size} samples in both train and test")
    if np.unique(both).size != n:
        out.append(f"{file}: the split covers {np.unique(both).size} of {n} samples")
    for name in ("subject_id", "instance_id"):
        if f"samples/{name}" in f and not out:
            ids = f[f"samples/{name}"][()]
            shared = set(ids[train].tolist()) & set(ids[test].tolist()) - {-1}
            if shared:
                out.append(f"{file}: {name} {sorted(shared)[:5]} on both sides of the split")
    return out


def _info(f: h5py.File, file: Path, fields: list[str], n: int) -> list[str]:
    out = []
    if f.attrs.get("format") != FORMAT or int(f.attrs.get("n_samples", -1)) != n:
        out.append(f"{file}: root attrs format/n_samples are not {FORMAT}/{n}")
    path = file.with_name(INFO)
    try:
        info = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as err:
        return [*out, f"{path} cannot be read ({err}). {repair_hint(file)}"]
    if not isinstance(info, dict) or not isinstance(info.get("fields"), dict):
        what = (
            json_kind(info)
            if not isinstance(info, dict)
            else f"fields {json_kind(info.get('fields'))}"
        )
        return [*out, f"{path}: {what}, not the sidecar merge writes. {repair_hint(file)}"]
    if info.get("n_samples") != n or sorted(info["fields"]) != sorted(fields):
        out.append(f"{path}: its samples or fields differ from {file.name}'s. {repair_hint(file)}")
    return out


def _chunks(folder: Path, report: Report, progress: bool) -> None:
    """Every chunk file still in ``chunks/`` opens and reads; a damaged one is named."""
    names = [STATIC] * (folder / CHUNKS / STATIC).is_file()
    names += [f"chunk_{k:06d}.h5" for k in list_chunks(folder)]
    if not names:
        return
    faults = []
    for name in tqdm(names, desc=CHUNKS, disable=not progress, leave=False):
        path = folder / CHUNKS / name
        try:
            with open_h5(path) as f:
                damaged = [ds for ds in _numeric(f) if bad_rows(ds, ()) is not None]
                faults += [str(read_error(d, d.name.rsplit("/", 1)[-1], path)) for d in damaged]
        except DataError as err:
            faults.append(str(err))
    report.check(faults, f"{CHUNKS}/: {len(names)} files read")
