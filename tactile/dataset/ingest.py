"""Turn a real skin recording into a dataset folder of the same format as the synthetic data.

Inputs (formats in ``docs/dataset_format.md``):

- a layout file, anything :meth:`TaxelLayout.load` reads (iCub ``.txt``, ``.csv``, ``.npz``);
- frames, ``.csv`` or ``.npy``, one frame per row: either raw channel frames (T, C), C =
  ``layout.n_channels`` (mapped with ``layout.taxels_from_channels``), or taxel frames (T, N);
  values are integer counts in 0..65535;
- optional baseline frames (B, same width), averaged into the untouched reading per taxel;
- optional per-frame class labels (T,): ``1``/``hand`` or ``0``/``non_hand``;
- optional per-taxel part labels (T, N): 0..6 (``tactile.CLASS_NAMES``).

Pressure is ``max(taxel reading - baseline, 0) / counts_per_pa`` (counts when counts_per_pa = 1),
the image is ``TactileMap.image`` of it, the label image ``TactileMap.label_image``. Every input is
read and checked before anything is written; each error names the file, the row and the fix.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tactile.dataset.readout import count_fault
from tactile.dataset.writer import DatasetWriter
from tactile.errors import DataError
from tactile.geometry.layout import TaxelLayout
from tactile.images.labels import N_CLASSES
from tactile.images.tactile_map import TactileMap

GENERATOR_VERSION = "ingest/1"
CHUNK_FRAMES = 256  # frames per chunk file: ~1-3 MB of images at 1 mm/px
CLASS_WORDS = {"1": 1, "hand": 1, "0": 0, "non_hand": 0, "non-hand": 0, "nonhand": 0}


@dataclass(frozen=True)
class Table:
    """Cells of a CSV or NPY file: values (R, C) (str cells for CSV), ``where[r]`` names row r."""

    path: Path
    values: np.ndarray
    where: list[str]


def read_table(path: str | Path, what: str) -> Table:
    """Read a ``.csv`` (comma-separated, ``#`` comments, optional header row) or ``.npy`` (1-D or
    2-D) file as rows of cells. ``what`` names the file's role in messages."""
    path = Path(path)
    if path.suffix.lower() not in (".csv", ".npy"):
        raise DataError(f"{path}: {what} must be a .csv or .npy file, not {path.suffix!r}")
    if not path.is_file():
        raise DataError(f"{path}: {what} file not found. Fix: check the path")
    table = _read_npy(path) if path.suffix.lower() == ".npy" else _read_csv(path)
    if len(table.values) == 0:
        raise DataError(f"{path}: {what} file holds no rows. Fix: give at least one frame")
    return table


def _read_npy(path: Path) -> Table:
    try:
        arr = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as err:
        raise DataError(f"{path}: not a readable .npy file ({err})") from err
    if arr.ndim not in (1, 2):
        raise DataError(f"{path}: expected a 1-D or 2-D array, got shape {arr.shape}")
    arr = arr.reshape(len(arr), -1)
    return Table(path, arr, [f"row {r}" for r in range(len(arr))])


def _read_csv(path: Path) -> Table:
    lines = [(n, t.strip()) for n, t in enumerate(path.read_text("utf-8").splitlines(), 1)]
    body = [(n, [c.strip() for c in t.split(",")]) for n, t in lines if t and t[0] != "#"]
    if body and not any(_is_number(c) for c in body[0][1]) and not _is_class_word(body[0][1]):
        body = body[1:]  # a header row (e.g. ch0,ch1,...)
    width = len(body[0][1]) if body else 0
    for n, cells in body:
        if len(cells) != width:
            raise DataError(
                f"{path}, line {n}: {len(cells)} values, but the first row has {width}. "
                "Fix: give every row the same number of comma-separated values"
            )
    values = np.array([c for _, c in body], dtype=object).reshape(len(body), width)
    return Table(path, values, [f"line {n}" for n, _ in body])


def _is_number(cell: str) -> bool:
    try:
        float(cell)
    except ValueError:
        return False
    return True


def _is_class_word(cells: list[str]) -> bool:
    return len(cells) == 1 and cells[0].lower() in CLASS_WORDS


def numbers(table: Table, what: str) -> np.ndarray:
    """The table as float64 (R, C); DataError naming the row and column of a non-number/NaN."""
    try:
        arr = table.values.astype(np.float64)
    except (ValueError, TypeError):
        arr = None
    if arr is None:
        for r, row in enumerate(table.values):
            bad = next((c for c, cell in enumerate(row) if not _is_number(str(cell))), None)
            if bad is not None:
                raise DataError(
                    f"{table.path}, {table.where[r]}, column {bad + 1}: {what} value "
                    f"{row[bad]!r} is not a number. Fix: write plain numbers"
                )
        raise DataError(f"{table.path}: {what} values are not numbers. Fix: write plain numbers")
    return _finite(table, arr, what)


def _finite(table: Table, arr: np.ndarray, what: str) -> np.ndarray:
    bad = np.argwhere(~np.isfinite(arr))
    if bad.size:
        r, c = bad[0]
        raise DataError(
            f"{table.path}, {table.where[r]}, column {c + 1}: {what} value is {arr[r, c]}. "
            "Fix: remove or repair the frame (NaN/inf are not readings)"
        )
    return arr


def counts(table: Table, what: str) -> np.ndarray:
    """Raw counts (R, C) float64: integers in 0..65535, else DataError naming row and column."""
    arr = numbers(table, what)
    fault = count_fault(arr)
    if fault is not None:
        (r, c), rule = fault
        raise DataError(
            f"{table.path}, {table.where[r]}, column {c + 1}: {what} value {arr[r, c]:g} is "
            f"{rule}. Fix: give raw sensor counts (subtract nothing, scale nothing)"
        )
    return arr


def to_taxels(table: Table, arr: np.ndarray, layout: TaxelLayout, what: str) -> np.ndarray:
    """(R, C) channel frames or (R, N) taxel frames -> (R, N) float64 taxel readings."""
    width, n = arr.shape[1], layout.n_taxels
    if layout.channel_ids is not None and width == layout.n_channels:
        return layout.taxels_from_channels(arr)
    if width == n:
        return arr
    channels = f"{layout.n_channels} (raw channel frames) or " if layout.n_channels else ""
    raise DataError(
        f"{table.path}: {what} rows have {width} values; layout {layout.name!r} needs {channels}"
        f"{n} (taxel frames). Fix: check that the frames belong to this layout"
    )


def class_labels(table: Table, n_frames: int) -> np.ndarray:
    """(T,) uint8 hand (1) / non-hand (0) from one column of 0/1 or hand/non_hand words."""
    _check_rows(table, n_frames, 1, "class labels", "one value per frame")
    out = np.empty(n_frames, np.uint8)
    for r, cell in enumerate(table.values[:, 0]):
        word = str(cell).strip().lower()
        word = str(int(float(word))) if _is_number(word) and float(word) in (0, 1) else word
        if word not in CLASS_WORDS:
            raise DataError(
                f"{table.path}, {table.where[r]}: unknown class label {cell!r}; accepted: "
                "1 or hand, 0 or non_hand. Fix: relabel that frame"
            )
        out[r] = CLASS_WORDS[word]
    return out


def part_labels(table: Table, n_frames: int, n_taxels: int) -> np.ndarray:
    """(T, N) uint8 part labels 0..6, else DataError naming row and column."""
    _check_rows(table, n_frames, n_taxels, "part labels", "one row per frame, one column per taxel")
    arr = numbers(table, "part label")
    bad = (arr < 0) | (arr >= N_CLASSES) | (arr != np.round(arr))
    if bad.any():
        r, c = np.argwhere(bad)[0]
        raise DataError(
            f"{table.path}, {table.where[r]}, column {c + 1}: unknown part label {arr[r, c]:g}; "
            f"accepted: integers 0..{N_CLASSES - 1} (tactile.CLASS_NAMES). Fix: relabel it"
        )
    return arr.astype(np.uint8)


def _check_rows(table: Table, rows: int, cols: int, what: str, rule: str) -> None:
    if table.values.shape != (rows, cols):
        raise DataError(
            f"{table.path}: {what} have shape {table.values.shape}, expected ({rows}, {cols}): "
            f"{rule}, matching the frames file"
        )


def _sha256(path: str | Path | None) -> str | None:
    return None if path is None else hashlib.sha256(Path(path).read_bytes()).hexdigest()


@dataclass(frozen=True)
class Recording:
    """A checked recording: layout; taxels (T, N) float64 counts; baseline (N,) float64 counts;
    hand (T,) uint8 or None; parts (T, N) uint8 or None."""

    layout: TaxelLayout
    taxels: np.ndarray
    baseline: np.ndarray
    hand: np.ndarray | None
    parts: np.ndarray | None


def read_recording(
    layout_path: str | Path,
    frames_path: str | Path,
    *,
    labels_path: str | Path | None = None,
    part_labels_path: str | Path | None = None,
    baseline_path: str | Path | None = None,
) -> Recording:
    """Read and check every input file (DataError naming file, row and fix; nothing written)."""
    layout = TaxelLayout.load(layout_path)
    frames_t = read_table(frames_path, "frames")
    taxels = to_taxels(frames_t, counts(frames_t, "frame"), layout, "frame")
    baseline = np.zeros(layout.n_taxels)
    if baseline_path is not None:
        base_t = read_table(baseline_path, "baseline")
        baseline = to_taxels(base_t, counts(base_t, "baseline"), layout, "baseline").mean(axis=0)
    n = len(taxels)
    hand = None if labels_path is None else class_labels(read_table(labels_path, "labels"), n)
    parts = None
    if part_labels_path is not None:
        parts = part_labels(read_table(part_labels_path, "part labels"), n, layout.n_taxels)
    return Recording(layout, taxels, baseline, hand, parts)


def ingest_recording(
    layout_path: str | Path,
    frames_path: str | Path,
    out_dir: str | Path,
    *,
    labels_path: str | Path | None = None,
    part_labels_path: str | Path | None = None,
    baseline_path: str | Path | None = None,
    step_mm: float = 1.0,
    counts_per_pa: float = 1.0,
) -> Path:
    """Ingest a recording (see the module docstring) into ``out_dir``; return its dataset.h5.

    step_mm : image grid step, mm/pixel. counts_per_pa : skin gain, counts/Pa (1.0: pressures in
    counts). Raises DataError (LayoutError/MapError for the layout) before writing anything.
    """
    if not (np.isfinite(counts_per_pa) and counts_per_pa > 0):
        raise DataError(f"counts_per_pa must be a positive count/Pa, got {counts_per_pa}")
    sources = {
        "layout": layout_path,
        "frames": frames_path,
        "labels": labels_path,
        "part_labels": part_labels_path,
        "baseline": baseline_path,
    }
    rec = read_recording(**{f"{k}_path": v for k, v in sources.items()})
    tmap = TactileMap.build(rec.layout, step_mm=step_mm)
    config = {
        "source": "ingest",
        "files": {k: None if v is None else Path(v).name for k, v in sources.items()},
        "sha256": {k: _sha256(v) for k, v in sources.items()},
        "step_mm": float(step_mm),
        "counts_per_pa": float(counts_per_pa),
    }
    writer = DatasetWriter(
        out_dir,
        config=config,
        part=rec.layout.name or Path(layout_path).stem,
        generator_version=GENERATOR_VERSION,
        seed=0,
        tmap=tmap,
        layout=rec.layout,
        attrs={"skin_counts_per_pa": float(counts_per_pa), "skin_baseline_counts": rec.baseline},
    )
    pressure = np.maximum(rec.taxels - rec.baseline, 0.0) / counts_per_pa
    done = set(writer.complete_chunks())
    for k, start in enumerate(range(0, len(pressure), CHUNK_FRAMES)):
        if k not in done:
            rows = slice(start, start + CHUNK_FRAMES)
            writer.write_chunk(k, _samples(tmap, rec, pressure[rows], rows))
    return writer.merge(n_chunks=k + 1)


def _samples(
    tmap: TactileMap, rec: Recording, pressure: np.ndarray, rows: slice
) -> list[dict[str, object]]:
    """Sample dicts of frames ``rows``: raw (rounded taxel readings), pressure, image, labels."""
    images = tmap.image(pressure)
    out = []
    for j, p in enumerate(pressure):
        i = rows.start + j
        sample: dict[str, object] = {
            "raw": np.rint(rec.taxels[i]).astype(np.uint16),
            "pressure_pa": p.astype(np.float32),
            "image": images[j],
        }
        if rec.hand is not None:
            sample["is_hand"] = rec.hand[i]
        if rec.parts is not None:
            sample["taxel_label"] = rec.parts[i]
            is_hand = rec.hand is None or rec.hand[i] == 1
            blank = np.zeros_like(images[j])
            sample["label_image"] = tmap.label_image(p, rec.parts[i]) if is_hand else blank
        out.append(sample)
    return out
