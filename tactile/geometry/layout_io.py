"""Readers and writers of taxel layouts: iCub calibration ``.txt``, plain xyz ``.txt``, the
project's ``.csv`` and ``.npz``. Formats and the iCub reading policy: ``docs/layout_formats.md``.

A reader returns the keyword arguments of `tactile.geometry.layout.TaxelLayout` (``positions_m`` (N,
3) float, m; optional ``normals``, ``module_ids``, ``channel_ids``, ``merged_channels``,
``n_channels``; ``name``), which validates them; a writer takes the same fields as a mapping.
`TaxelLayout.load` and `TaxelLayout.save` are the entry points.

Every error is a LayoutError naming the file, the 1-based line when there is one, and the fix;
a missing or binary file, or one of more than ``MAX_TAXELS`` rows, is refused before parsing.
Writes are atomic (temporary file in the same folder, then ``os.replace``).
"""

from __future__ import annotations

import re
import warnings
from collections.abc import Callable, Mapping
from os import PathLike
from pathlib import Path
from typing import IO, Any

import numpy as np

from tactile.errors import LayoutError
from tactile.files import atomic_path, count_lines, require_input, text_lines

# Taxels a layout may hold. A tactile map's build time grows faster than its taxel count (about a
# minute at 100,000 taxels, measured with TactileMap.build), and robot skins hold thousands (the
# iCub's whole body about 4,000): a larger file is almost surely not one row per taxel.
MAX_TAXELS = 100_000
FORMAT_VERSION = 1
CSV_MAGIC = f"# handskin taxel layout v{FORMAT_VERSION}"
UNIT_SCALE = {"m": 1.0, "mm": 1e-3}  # metres per file unit
PADS_PER_MODULE = 12  # iCub triangle: channel i is pad i % 12 of triangle i // 12
ICUB_KEYS = ("name", "spatial_sampling", "taxel2Repr", "[calibration]")
CSV_OPTIONAL = ("nx", "ny", "nz", "module", "channel", "merged_channels")
SUFFIX_HELP = "accepted suffixes: .npz, .csv, .txt (iCub calibration or plain xyz)"

Lines = list[tuple[int, str]]  # (1-based line number, text)
Fields = dict[str, Any]  # keyword arguments of TaxelLayout


def read_layout(path: str | PathLike[str], *, units: str | None = None) -> Fields:
    """The layout fields in ``path``, dispatching on the suffix (see `TaxelLayout.load`)."""
    path = Path(path)
    if units is not None and units not in UNIT_SCALE:
        raise LayoutError(f"{path}: unknown unit {units!r} (--units); accepted units: m, mm")
    readers = {".npz": read_npz, ".csv": read_csv, ".txt": read_txt}
    if path.suffix.lower() not in readers:
        raise LayoutError(f"{path}: unknown suffix {path.suffix!r}; {SUFFIX_HELP}")
    require_input(path, "layout", LayoutError)
    lines = 0 if path.suffix.lower() == ".npz" else count_lines(path)
    if lines > MAX_TAXELS + 1000:
        too_many(path, f"{lines:,} lines")
    return readers[path.suffix.lower()](path, units)


def too_many(path: Path | str, found: str) -> None:
    """LayoutError: the layout holds more than MAX_TAXELS taxels (``found`` says how many)."""
    raise LayoutError(
        f"{path}: {found}, more than the {MAX_TAXELS:,} taxels handskin maps (a tactile map "
        "takes about a minute to build at 100,000 taxels, and robot skins hold thousands). "
        "Fix: check that the file has one row per taxel, or split the skin into parts"
    )


def write_layout(layout: Mapping[str, Any], path: str | PathLike[str]) -> None:
    """Write layout fields to ``.npz`` or ``.csv`` atomically; a failed write leaves any existing
    file untouched."""
    path = Path(path)
    if path.suffix.lower() == ".npz":
        _atomic_write(path, "wb", lambda fh: write_npz(layout, fh))
    elif path.suffix.lower() == ".csv":
        _check_csv_name(path, layout["name"])
        _atomic_write(path, "w", lambda fh: fh.write(csv_text(layout)))
    else:
        raise LayoutError(f"{path}: cannot save to suffix {path.suffix!r}; use .npz or .csv")


def _atomic_write(path: Path, mode: str, write: Callable[[IO[Any]], object]) -> None:
    with (
        atomic_path(path) as tmp,
        open(tmp, mode, **({} if "b" in mode else {"encoding": "utf-8"})) as fh,
    ):
        write(fh)


def _numbered_lines(path: Path) -> Lines:
    return list(enumerate(text_lines(path, "layout", LayoutError), start=1))


def _floats(path: Path, line: int, tokens: list[str], what: str, count: int = 0) -> np.ndarray:
    """Parse tokens (``count`` of them if > 0) as finite floats, or raise naming file and line."""
    if count and len(tokens) != count:
        raise LayoutError(
            f"{path}, line {line}: {len(tokens)} values, expected {count} ({what}). "
            "Fix: one value per column"
        )
    values = []
    for token in tokens:
        try:
            values.append(float(token))
        except ValueError:
            raise LayoutError(
                f"{path}, line {line}: {token!r} is not a number ({what}). Fix: correct it"
            ) from None
    if not np.all(np.isfinite(values)):
        raise LayoutError(f"{path}, line {line}: NaN or inf in {what}. Fix: repair the row")
    return np.array(values, dtype=np.float64)


# ---- npz --------------------------------------------------------------------------------------


def write_npz(layout: Mapping[str, Any], fh: IO[bytes]) -> None:
    """All fields, absent optional arrays omitted, n_channels -1 when None."""
    arrays = {
        key: layout[key]
        for key in ("normals", "module_ids", "channel_ids", "merged_channels")
        if layout[key] is not None
    }
    n_channels = layout["n_channels"]
    arrays["n_channels"] = np.int64(-1 if n_channels is None else n_channels)
    arrays["format_version"] = np.int64(FORMAT_VERSION)
    np.savez(fh, positions_m=layout["positions_m"], name=np.str_(layout["name"]), **arrays)


def read_npz(path: Path, units: str | None) -> Fields:
    """Read a file written by `write_npz` (always metres)."""
    if units not in (None, "m"):
        raise LayoutError(f"{path}: .npz layouts are in metres; leave out --units {units}")
    try:
        with np.load(path, allow_pickle=False) as data:
            fields = {key: data[key] for key in data.files}
    except (OSError, ValueError) as err:
        why = "not a NumPy .npz archive" if "pickle" in str(err) else str(err).splitlines()[0]
        raise LayoutError(
            f"{path}: not a readable .npz layout ({why}). Fix: save it with TaxelLayout.save"
        ) from None
    version = int(fields.pop("format_version", -1))
    if version != FORMAT_VERSION or "positions_m" not in fields:
        raise LayoutError(
            f"{path}: not a handskin layout v{FORMAT_VERSION} (format_version={version}, "
            f"keys {sorted(fields)}). Fix: save it with TaxelLayout.save"
        )
    if len(fields["positions_m"]) > MAX_TAXELS:
        too_many(path, f"{len(fields['positions_m']):,} taxels")
    n_ch = int(fields.pop("n_channels", -1))
    name = str(fields.pop("name", ""))
    return {"n_channels": None if n_ch < 0 else n_ch, "name": name, **fields}


# ---- csv --------------------------------------------------------------------------------------


def _check_csv_name(path: Path, name: str) -> None:
    if "\n" in name or "\r" in name:
        raise LayoutError(f"{path}: layout name {name!r} has a line break. Fix: rename it")


def csv_text(layout: Mapping[str, Any]) -> str:
    """The documented CSV: comment block, header row with units, one row per taxel (metres)."""
    head = [CSV_MAGIC, f"# name: {layout['name']}"]
    if layout["n_channels"] is not None:
        head.append(f"# n_channels: {layout['n_channels']}")
    positions, normals = layout["positions_m"], layout["normals"]
    n_taxels = len(positions)
    columns: list[tuple[str, list[str]]] = [
        (f"{axis}_m", [repr(float(v)) for v in positions[:, i]]) for i, axis in enumerate("xyz")
    ]
    if normals is not None:
        columns += [(f"n{a}", [repr(float(v)) for v in normals[:, i]]) for i, a in enumerate("xyz")]
    for key, ids in (("module", layout["module_ids"]), ("channel", layout["channel_ids"])):
        if ids is not None:
            columns.append((key, [str(int(v)) for v in ids]))
    if layout["merged_channels"] is not None:
        extra: list[list[str]] = [[] for _ in range(n_taxels)]
        for channel, taxel in layout["merged_channels"]:
            extra[taxel].append(str(int(channel)))
        columns.append(("merged_channels", [" ".join(e) for e in extra]))
    rows = [",".join(col[1][r] for col in columns) for r in range(n_taxels)]
    return "\n".join([*head, ",".join(c[0] for c in columns), *rows]) + "\n"


def read_csv(path: Path, units: str | None) -> Fields:
    """Read the documented CSV (see ``docs/layout_formats.md``)."""
    lines = [(n, t) for n, t in _numbered_lines(path) if t.strip()]
    meta = _csv_meta(path, [(n, t) for n, t in lines if t.lstrip().startswith("#")])
    body = [(n, t) for n, t in lines if not t.lstrip().startswith("#")]
    if not body:
        raise LayoutError(f"{path}: no header row. Fix: add e.g. 'x_m,y_m,z_m' before the rows")
    header_line, header = body[0][0], [c.strip() for c in body[0][1].split(",")]
    scale = _csv_units(path, header_line, header, units)
    cols: dict[str, list[str]] = {c: [] for c in header}
    for line, text in body[1:]:
        cells = [c.strip() for c in text.split(",")]
        if len(cells) != len(header):
            _floats(path, line, cells, f"columns {','.join(header)}", len(header))
        for c, v in zip(header, cells, strict=True):
            cols[c].append(v)
    return {
        "name": meta.get("name", path.stem),
        "n_channels": meta.get("n_channels"),
        **_csv_fields(path, [n for n, _ in body[1:]], header, cols, scale),
    }


def _csv_meta(path: Path, comments: Lines) -> dict[str, Any]:
    meta: dict[str, Any] = {}
    for line, text in comments:
        version = re.match(r"#\s*handskin taxel layout v(\d+)", text)
        if version and int(version.group(1)) != FORMAT_VERSION:
            raise LayoutError(
                f"{path}, line {line}: layout CSV v{version.group(1)} is not "
                f"supported (this reader: v{FORMAT_VERSION}). Fix: update handskin"
            )
        key, sep, value = text.lstrip("# ").partition(":")
        if sep and key.strip() == "name":
            meta["name"] = value[1:] if value.startswith(" ") else value
        elif sep and key.strip() == "n_channels":
            meta["n_channels"] = int(_floats(path, line, [value.strip()], "n_channels")[0])
    return meta


def _csv_units(path: Path, line: int, header: list[str], units: str | None) -> float:
    """Metres per file unit, from the x/y/z column names (or ``units`` for plain x,y,z)."""
    pos = [c for c in header if re.fullmatch(r"[xyz](_.*)?", c)]
    suffixes = {c.partition("_")[2] for c in pos}
    fix = (
        "Fix: name the columns x_m,y_m,z_m or x_mm,y_mm,z_mm, or give the unit of plain x,y,z "
        "(--units m or mm; in Python units='m' or 'mm')"
    )
    unknown = [c for c in header if c not in pos and c not in CSV_OPTIONAL]
    if unknown or sorted(c[0] for c in pos) != ["x", "y", "z"] or len(suffixes) != 1:
        raise LayoutError(
            f"{path}, line {line}: header {header} must have one x, y and z column "
            f"with the same unit and only optional columns {list(CSV_OPTIONAL)}"
            f"{f'; unknown columns {unknown}' if unknown else ''}. {fix}"
        )
    unit = suffixes.pop() or units
    if unit is None or unit not in UNIT_SCALE:
        got = "no unit" if unit is None else f"unknown unit {unit!r}"
        raise LayoutError(
            f"{path}, line {line}: position columns have {got}; accepted units: m, mm. {fix}"
        )
    if units is not None and units != unit:
        raise LayoutError(
            f"{path}, line {line}: columns say {unit!r} but --units says {units!r}. "
            "Fix: leave --units out"
        )
    return UNIT_SCALE[unit]


def _csv_fields(
    path: Path, row_lines: list[int], header: list[str], cols: dict[str, list[str]], scale: float
) -> dict[str, Any]:
    def numbers(names: list[str], what: str) -> np.ndarray:
        rows = zip(*(cols[n] for n in names), strict=True)
        values = [
            _floats(path, line, list(r), what) for line, r in zip(row_lines, rows, strict=True)
        ]
        return np.array(values)

    xyz = [next(c for c in header if c.startswith(a)) for a in "xyz"]
    fields: dict[str, Any] = {"positions_m": numbers(xyz, "x, y, z").reshape(-1, 3) * scale}
    if any(n in cols for n in ("nx", "ny", "nz")):
        if not all(n in cols for n in ("nx", "ny", "nz")):
            raise LayoutError(f"{path}: give all of the columns nx, ny, nz or none of them")
        fields["normals"] = numbers(["nx", "ny", "nz"], "nx, ny, nz").reshape(-1, 3)
    for col, key in (("module", "module_ids"), ("channel", "channel_ids")):
        if col in cols:
            fields[key] = numbers([col], col).reshape(-1)
    if "merged_channels" in cols:
        pairs = [
            (int(ch), taxel)
            for taxel, cell in enumerate(cols["merged_channels"])
            for ch in _floats(path, row_lines[taxel], cell.split(), "merged_channels")
        ]
        fields["merged_channels"] = np.array(pairs, dtype=np.int64).reshape(-1, 2)
    return fields


# ---- txt: iCub calibration or plain xyz -------------------------------------------------------


def read_txt(path: Path, units: str | None) -> Fields:
    """An iCub calibration file if it has iCub header keys, else plain xyz (needs ``units``)."""
    lines = _numbered_lines(path)
    if any(t.split()[0] in ICUB_KEYS for _, t in lines if t.split()):
        return read_icub(path, lines, UNIT_SCALE[units or "m"])
    return read_xyz(path, lines, units)


def read_xyz(path: Path, lines: Lines, units: str | None) -> Fields:
    """Plain text: one taxel per line, ``x y z`` or ``x y z nx ny nz`` ('#' comments, commas ok)."""
    if units is None:
        raise LayoutError(
            f"{path}: plain xyz text has no unit and no iCub header. Fix: give the unit "
            "(--units m or mm; in Python units='m' or 'mm'), or add the iCub '[calibration]' "
            "header"
        )
    rows = [(n, t.replace(",", " ").split()) for n, t in lines if t.strip() and t.strip()[0] != "#"]
    width = 6 if rows and len(rows[0][1]) == 6 else 3
    what = "x y z nx ny nz" if width == 6 else "x y z"
    data = np.array([_floats(path, n, t, what, width) for n, t in rows]).reshape(-1, width)
    normals = data[:, 3:] if width == 6 else None
    return {"positions_m": data[:, :3] * UNIT_SCALE[units], "normals": normals, "name": path.stem}


def read_icub(path: Path, lines: Lines, scale: float = 1.0) -> Fields:
    """iCub skinGui calibration file; policy in ``docs/layout_formats.md``.

    Keeps channels with a non-zero row whose taxel2Repr is >= 0 (or beyond its length); merges
    duplicate positions (one warning); channel i -> module i // 12.
    """
    cal = next((i for i, (_, t) in enumerate(lines) if t.strip() == "[calibration]"), None)
    if cal is None:
        raise LayoutError(
            f"{path}, lines 1-{len(lines)}: no '[calibration]' line. Fix: add a line "
            "'[calibration]' before the rows 'x y z nx ny nz' (metres)"
        )
    name, t2r = _icub_header(path, lines[:cal])
    rows = [(n, t.split()) for n, t in lines[cal + 1 :] if t.strip()]
    data = np.array([_floats(path, n, t, "x y z nx ny nz", 6) for n, t in rows]).reshape(-1, 6)
    keep = icub_taxel_channels(data, t2r)
    normals = icub_normals(path, data[keep, 3:], [rows[c][0] for c in keep])
    first, merged = merge_duplicates(data[keep, :3], keep)
    if merged.size:
        warnings.warn(
            f"{path}: {len(merged)} channels repeat the position of an earlier channel; "
            f"merged into {first.size} taxels (readings averaged)",
            stacklevel=5,
        )
    return {
        "positions_m": data[keep[first], :3] * scale,
        "normals": None if normals is None else normals[first],
        "module_ids": keep[first] // PADS_PER_MODULE,
        "channel_ids": keep[first],
        "merged_channels": merged,
        "n_channels": len(data),
        "name": name or path.stem,
    }


def _icub_header(path: Path, header: Lines) -> tuple[str, np.ndarray]:
    """The ``name`` value and the taxel2Repr integers (may span lines) of an iCub header."""
    text = "\n".join(t for _, t in header)
    name = re.search(r"^\s*name\s+(.*?)\s*$", text, re.MULTILINE)
    start = re.search(r"^\s*taxel2Repr", text, re.MULTILINE)
    if start is None:
        return (name.group(1) if name else ""), np.zeros(0, dtype=np.int64)
    values = re.match(r"\s*\(([-+\d\s]*)\)", text[start.end() :])
    if values is None:
        line = text[: start.start()].count("\n") + 1
        raise LayoutError(
            f"{path}, line {line}: taxel2Repr must be '( int int ... )'. Fix: correct that list"
        )
    return (name.group(1) if name else ""), np.array(values.group(1).split(), dtype=np.int64)


def icub_taxel_channels(data: np.ndarray, t2r: np.ndarray) -> np.ndarray:
    """Channels that are pressure taxels: a non-zero row and taxel2Repr >= 0 or undefined.

    data : (C, 6) float rows; t2r : (L,) int. Returns (K,) int64 channel indices, increasing.
    """
    t2r_full = np.zeros(len(data), dtype=np.int64)  # beyond taxel2Repr: trust the row
    t2r_full[: min(len(t2r), len(data))] = t2r[: len(data)]
    return np.flatnonzero(np.any(data != 0.0, axis=1) & (t2r_full >= 0))


def icub_normals(path: Path, normals: np.ndarray, line_numbers: list[int]) -> np.ndarray | None:
    """Unit normals (the files round them, |n| is 0.5-1), None if all zero, error if some are."""
    norm = np.linalg.norm(normals, axis=1)
    if np.all(norm == 0.0):
        return None
    if np.any(norm == 0.0):
        line = line_numbers[int(np.flatnonzero(norm == 0.0)[0])]
        raise LayoutError(
            f"{path}, line {line}: zero normal on a taxel while others have one. "
            "Fix: give that row its normal"
        )
    return normals / norm[:, None]


def merge_duplicates(positions: np.ndarray, channels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge channels with identical positions into the first one.

    positions : (K, 3) float; channels : (K,) int. Returns ``first`` (N,) int indices into the K
    rows (file order) and ``merged`` (D, 2) int64 rows (channel, taxel index into ``first``).
    """
    _, first_of_group, group = np.unique(positions, axis=0, return_index=True, return_inverse=True)
    group = group.reshape(-1)
    order = np.argsort(first_of_group)
    taxel_of_group = np.empty_like(order)
    taxel_of_group[order] = np.arange(order.size)
    extra = np.flatnonzero(first_of_group[group] != np.arange(len(positions)))
    merged = np.column_stack([channels[extra], taxel_of_group[group[extra]]]).astype(np.int64)
    return np.sort(first_of_group), merged.reshape(-1, 2)
