"""`TaxelLayout`: the 3D taxel positions of one skin part, validated once at construction.

The class is a thin frozen facade; the checks and the channel→taxel maths are small functions on
arrays below it. File formats (iCub calibration ``.txt``, ``.csv``, ``.npz``) are read and written
by `tactile.geometry.layout_io` (described in ``docs/layout_formats.md``); `TaxelLayout.load`
validates what it reads.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from os import PathLike
from pathlib import Path

import numpy as np

from tactile.errors import LayoutError, MapError
from tactile.geometry.layout_io import MAX_TAXELS, read_layout, write_layout

NORMAL_TOLERANCE = 1e-3  # |1 - |n|| below this is rounding and gets normalised; above, an error
COLLINEAR_RTOL = 1e-7  # RMS spread off the main axis, relative to the extent, below which = a line


def _float_matrix(values: object, name: str, n_rows: int | None) -> np.ndarray:
    """A (n_rows, 3) float64 copy of ``values``, finite, or LayoutError naming the first bad row."""
    arr = np.array(values, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3 or (n_rows is not None and arr.shape[0] != n_rows):
        want = f"({n_rows if n_rows is not None else 'N'}, 3)"
        raise LayoutError(f"{name} has shape {arr.shape}; expected {want}")
    bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
    if bad.size:
        raise LayoutError(
            f"{name} row {bad[0]} is not finite ({arr[bad[0]]}); {bad.size} bad rows in all. "
            "Fix: remove or repair those rows"
        )
    return arr


def _int_array(values: object, name: str, shape: tuple[int | None, ...]) -> np.ndarray:
    """An int64 copy of ``values`` with the given shape (None = any length)."""
    raw = np.asarray(values)
    if raw.dtype.kind not in "iu" and not (
        raw.dtype.kind == "f" and np.all(np.isfinite(raw)) and np.all(raw == np.round(raw))
    ):
        raise LayoutError(f"{name} must hold integers; got dtype {raw.dtype}")
    arr = raw.astype(np.int64)
    ok = arr.ndim == len(shape) and all(
        s is None or s == a for s, a in zip(shape, arr.shape, strict=True)
    )
    if not ok:
        want = "(" + ", ".join("any" if s is None else str(s) for s in shape) + ")"
        raise LayoutError(f"{name} has shape {arr.shape}; expected {want}")
    return arr


def unit_normals(normals: np.ndarray, tol: float = NORMAL_TOLERANCE) -> np.ndarray:
    """Normalise rows within ``tol`` of unit length; LayoutError naming the first row beyond it.

    normals : (N, 3) float. Returns (N, 3) float, unit rows.
    """
    norm = np.linalg.norm(normals, axis=1)
    bad = np.flatnonzero(np.abs(norm - 1.0) > tol)
    if bad.size:
        raise LayoutError(
            f"normals row {bad[0]} has length {norm[bad[0]]:.6g}, not 1 (tolerance {tol}); "
            f"{bad.size} such rows. Fix: pass unit normals (n / |n|) or normals=None"
        )
    return normals / norm[:, None]


def check_spread(positions_m: np.ndarray, rtol: float = COLLINEAR_RTOL) -> None:
    """LayoutError unless there are >= 3 points, not all on one line.

    positions_m : (N, 3) float, m. Collinear when the RMS distance from the principal axis (second
    singular value of the centred points / sqrt(N)) is below ``rtol`` times the largest extent.
    """
    n = positions_m.shape[0]
    if n < 3:
        raise LayoutError(f"a layout needs at least 3 taxels, got {n}. Fix: add taxels")
    centred = positions_m - positions_m.mean(axis=0)
    extent = float(np.ptp(positions_m, axis=0).max())
    sing = np.linalg.svd(centred, compute_uv=False)
    if extent == 0.0 or sing[1] / np.sqrt(n) <= rtol * extent:
        raise LayoutError(
            f"all {n} taxel positions lie on one line (or one point); a skin layout needs a "
            "surface. Fix: check the units and the position columns"
        )


def check_channels(
    channel_ids: np.ndarray, merged: np.ndarray | None, n_taxels: int, n_channels: int | None
) -> int:
    """Check channel ids and merged rows; return n_channels (default: largest channel + 1)."""
    all_ch = channel_ids if merged is None else np.concatenate([channel_ids, merged[:, 0]])
    if all_ch.size and all_ch.min() < 0:
        raise LayoutError(f"channel ids must be >= 0; found {all_ch.min()}")
    uniq, counts = np.unique(all_ch, return_counts=True)
    if np.any(counts > 1):
        raise LayoutError(f"channel {uniq[counts > 1][0]} is assigned to more than one taxel")
    if (
        merged is not None
        and merged.size
        and not (0 <= merged[:, 1].min() <= merged[:, 1].max() < n_taxels)
    ):
        raise LayoutError(f"merged_channels taxel column must lie in [0, {n_taxels})")
    needed = int(all_ch.max()) + 1 if all_ch.size else 0
    if n_channels is None:
        return needed
    if int(n_channels) < needed:
        raise LayoutError(f"n_channels={n_channels} but channel {needed - 1} is used")
    return int(n_channels)


def channels_to_taxels(
    frame: np.ndarray, channel_ids: np.ndarray, merged: np.ndarray | None, n_taxels: int
) -> np.ndarray:
    """Per-taxel readings: the mean of the channels merged into each taxel.

    frame : (..., C) float, raw channel readings. Returns (..., N) float.
    """
    out = frame[..., channel_ids].astype(np.float64)
    if merged is None or merged.size == 0:
        return out
    counts = np.bincount(merged[:, 1], minlength=n_taxels) + 1.0
    flat = out.reshape(-1, n_taxels)
    np.add.at(
        flat, (slice(None), merged[:, 1]), frame.reshape(-1, frame.shape[-1])[:, merged[:, 0]]
    )
    return (flat / counts).reshape(out.shape)


def _readonly(arr: np.ndarray | None) -> np.ndarray | None:
    if arr is not None:
        arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class TaxelLayout:
    """Taxels of one skin part: positions, optional normals, module and raw channel ids.

    Attributes
    ----------
    positions_m : (N, 3) float64, m.
    normals : (N, 3) float64, unit, outward; or None.
    module_ids : (N,) int64, module (triangle) id, -1 unknown; or None.
    channel_ids : (N,) int64, raw channel read by each taxel; or None.
    merged_channels : (D, 2) int64 rows (channel, taxel), sorted: extra channels whose duplicate
        position was merged into ``taxel``; or None. Needs ``channel_ids``.
    n_channels : int, length of one raw frame (absent channels included); or None without ids.
    name : str.

    All arrays are copied and read-only. Raises LayoutError on bad shapes, non-finite values,
    fewer than 3 taxels, collinear positions, non-unit normals or inconsistent ids.
    """

    positions_m: np.ndarray = field(repr=False)
    normals: np.ndarray | None = field(default=None, repr=False)
    module_ids: np.ndarray | None = field(default=None, repr=False)
    channel_ids: np.ndarray | None = field(default=None, repr=False)
    merged_channels: np.ndarray | None = field(default=None, repr=False)
    n_channels: int | None = None
    name: str = ""

    def __post_init__(self) -> None:
        pos = _float_matrix(self.positions_m, "positions_m", None)
        if len(pos) > MAX_TAXELS:
            raise LayoutError(
                f"{len(pos):,} taxels: more than the {MAX_TAXELS:,} a tactile map is built for "
                "(about a minute at 100,000). Fix: split the skin into parts"
            )
        check_spread(pos)
        n = pos.shape[0]
        normals = None
        if self.normals is not None:
            normals = unit_normals(_float_matrix(self.normals, "normals", n))
        modules = (
            None if self.module_ids is None else _int_array(self.module_ids, "module_ids", (n,))
        )
        channels, merged, n_channels = self._channels(n)
        for key, value in [
            ("positions_m", pos),
            ("normals", normals),
            ("module_ids", modules),
            ("channel_ids", channels),
            ("merged_channels", merged),
            ("n_channels", n_channels),
            ("name", str(self.name)),
        ]:
            object.__setattr__(
                self, key, _readonly(value) if isinstance(value, np.ndarray) else value
            )

    def _channels(self, n: int) -> tuple[np.ndarray | None, np.ndarray | None, int | None]:
        if self.channel_ids is None:
            if self.merged_channels is not None:
                raise LayoutError("merged_channels given without channel_ids. Fix: pass both")
            n_ch = None if self.n_channels is None else int(self.n_channels)
            return None, None, n_ch
        channels = _int_array(self.channel_ids, "channel_ids", (n,))
        merged = None
        if self.merged_channels is not None:
            merged = _int_array(self.merged_channels, "merged_channels", (None, 2))
            merged = merged[np.lexsort((merged[:, 0], merged[:, 1]))]
        return channels, merged, check_channels(channels, merged, n, self.n_channels)

    def __repr__(self) -> str:
        return (
            f"TaxelLayout(name={self.name!r}, n_taxels={self.n_taxels}, "
            f"n_channels={self.n_channels}, normals={self.normals is not None})"
        )

    @property
    def n_taxels(self) -> int:
        """Number of taxels N."""
        return int(self.positions_m.shape[0])

    @classmethod
    def load(cls, path: str | PathLike[str], *, units: str | None = None) -> TaxelLayout:
        """Read a layout from ``.npz``, ``.csv`` or ``.txt`` (iCub calibration or plain xyz).

        ``units`` ("m" or "mm") gives the unit of plain ``x,y,z`` CSV columns and plain xyz text.
        LayoutError names the file (and line) of what is wrong.
        """
        found = read_layout(path, units=units)
        try:
            return cls(**found)
        except LayoutError as err:
            raise LayoutError(f"{Path(path)}: {err}") from None

    def save(self, path: str | PathLike[str]) -> None:
        """Write to ``.npz`` or ``.csv`` (by suffix), atomically: nothing is written on failure."""
        write_layout({f.name: getattr(self, f.name) for f in fields(self)}, path)

    def taxels_from_channels(self, frame: np.ndarray) -> np.ndarray:
        """Map a raw channel frame to per-taxel readings (merged duplicates averaged).

        frame : (C,) or (B, C) float, C = n_channels. Returns (N,) or (B, N) float64.
        """
        if self.channel_ids is None:
            raise LayoutError(
                f"layout {self.name!r} has no channel ids, so raw frames cannot be mapped. "
                "Fix: load it from a file with channels (iCub .txt, or .csv with a channel column)"
            )
        arr = np.asarray(frame)
        if arr.ndim not in (1, 2) or arr.shape[-1] != self.n_channels:
            raise MapError(
                f"frame has shape {arr.shape}; expected ({self.n_channels},) or "
                f"(B, {self.n_channels}) for layout {self.name!r}"
            )
        arr = arr.astype(np.float64)
        bad = np.argwhere(~np.isfinite(arr))
        if bad.size:
            raise MapError(f"frame has NaN or inf at index {tuple(bad[0])}. Fix: clean the frame")
        return channels_to_taxels(arr, self.channel_ids, self.merged_channels, self.n_taxels)

    def subset(self, keep: np.ndarray) -> TaxelLayout:
        """The layout restricted to taxels ``keep`` ((K,) int, strictly increasing, in [0, N)).

        Normals, module/channel ids and the merged channels of kept taxels follow (re-indexed).
        """
        keep = subset_indices(keep, self.n_taxels)
        merged = self.merged_channels
        return TaxelLayout(
            positions_m=self.positions_m[keep],
            normals=_take(self.normals, keep),
            module_ids=_take(self.module_ids, keep),
            channel_ids=_take(self.channel_ids, keep),
            merged_channels=None if merged is None else subset_merged(merged, keep, self.n_taxels),
            n_channels=self.n_channels,
            name=self.name,
        )


def subset_indices(keep: object, n_taxels: int) -> np.ndarray:
    """Validate taxel indices for `TaxelLayout.subset`: 1-D ints, strictly increasing, in range."""
    arr = np.asarray(keep)
    if arr.dtype == bool:
        raise LayoutError("keep is a boolean mask; pass indices. Fix: np.flatnonzero(mask)")
    arr = _int_array(arr, "keep", (None,))
    if arr.size and (arr.min() < 0 or arr.max() >= n_taxels):
        raise LayoutError(f"keep has indices outside [0, {n_taxels})")
    if np.any(np.diff(arr) <= 0):
        raise LayoutError("keep must be strictly increasing (sorted, unique). Fix: np.unique(keep)")
    return arr


def subset_merged(merged: np.ndarray, keep: np.ndarray, n_taxels: int) -> np.ndarray:
    """Merged (channel, taxel) rows of the kept taxels, with taxels re-indexed into ``keep``.

    merged : (D, 2) int; keep : (K,) int, strictly increasing. Returns (D', 2) int64.
    """
    new_index = np.full(n_taxels, -1, dtype=np.int64)
    new_index[keep] = np.arange(keep.size)
    kept = merged[new_index[merged[:, 1]] >= 0]
    return np.column_stack([kept[:, 0], new_index[kept[:, 1]]])


def _take(arr: np.ndarray | None, keep: np.ndarray) -> np.ndarray | None:
    return None if arr is None else arr[keep]
