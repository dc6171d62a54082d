"""The tactile map: a flat triangle mesh over the taxels and its pixel look-up table.

Albini & Cannata (IJRR 2020): the taxel cloud is triangulated and flattened, a regular grid of
``step_mm`` is laid over the flat map, and every grid point inside a triangle interpolates the
pressures of the triangle's three taxels. The table is computed once (:meth:`TactileMap.from_flat`
or :meth:`TactileMap.build`) and applied as a sparse matrix product at run time. The maths lives in
:mod:`tactile.images.raster`, :mod:`tactile.images.morphology` and :mod:`tactile.images.labels`;
this class is a thin frozen facade.
"""

from __future__ import annotations

import inspect
from dataclasses import dataclass
from functools import cached_property
from os import PathLike
from typing import TYPE_CHECKING

import numpy as np
import scipy.sparse as sp

import tactile.images.raster as raster
from tactile.errors import MapError
from tactile.geometry.distortion import DistortionReport, distortion_report
from tactile.geometry.flatten import flatten
from tactile.geometry.surface import triangulate
from tactile.images.labels import label_image
from tactile.images.morphology import erode_dilate

if TYPE_CHECKING:
    from tactile.geometry.layout import TaxelLayout

FORMAT = "handskin.tactile_map/1"
MAX_PIXELS = 50_000_000  # a larger grid means uv is not in mm or step_mm is far too small
_DISTORTION = ("area_ratio", "angle_error_deg", "edge_ratio")
_KEYS = ("format", "step_mm", "positions_m", "uv", "vertex_uv_mm", "vertex_taxel", "faces")
_KEYS += tuple(f"distortion_{k}" for k in (*_DISTORTION, "n_flipped"))


def _check_step(step_mm: float) -> float:
    if not (np.isscalar(step_mm) and np.isfinite(step_mm) and step_mm > 0):
        raise MapError(f"step_mm must be a positive number of mm, got {step_mm!r}")
    return float(step_mm)


def _readonly(*arrays: np.ndarray) -> tuple[np.ndarray, ...]:
    for arr in arrays:
        arr.flags.writeable = False
    return arrays


@dataclass(frozen=True, eq=False)
class TactileMap:
    """A flat taxel mesh and its pixel grid (rows = v, downwards; columns = u, the long axis).

    step_mm : float, mm per pixel. shape : (H, W) pixels. origin_mm : (2,) (u_min, v_max), mm.
    uv : (N, 2) float, mm — taxel uv (NaN unplaced). triangles : (M, 3) taxel indices.
    vertex_uv_mm : (V, 2) float, mm; vertex_taxel : (V,) int; faces : (M, 3) vertex indices.
    distortion : DistortionReport. positions_m : (N, 3) float, m.
    pixels : (P,) int — flat indices of the pixels inside the mesh.
    lut : (H * W, N) CSR float64 — the interpolation look-up table.
    """

    step_mm: float
    shape: tuple[int, int]
    origin_mm: np.ndarray
    uv: np.ndarray
    triangles: np.ndarray
    vertex_uv_mm: np.ndarray
    vertex_taxel: np.ndarray
    faces: np.ndarray
    distortion: DistortionReport
    positions_m: np.ndarray
    pixels: np.ndarray
    lut: sp.csr_matrix

    @classmethod
    def from_flat(
        cls,
        positions_m: np.ndarray,
        vertex_uv_mm: np.ndarray,
        vertex_taxel: np.ndarray,
        faces: np.ndarray,
        *,
        step_mm: float = 1.0,
        distortion: DistortionReport | None = None,
        taxel_uv_mm: np.ndarray | None = None,
    ) -> TactileMap:
        """Build the map and its look-up table from an explicit flat mesh.

        positions_m : (N, 3) float, m. vertex_uv_mm : (V, 2) float, mm. vertex_taxel : (V,) int.
        faces : (M, 3) int into the vertices (any orientation). step_mm : pixel size, mm.
        distortion : computed from the 3D positions when None. taxel_uv_mm : (N, 2) float, mm
        (NaN unplaced); by default each taxel's first vertex.
        """
        pos, uv_v, v_taxel, tri = raster.check_flat_mesh(
            positions_m, vertex_uv_mm, vertex_taxel, faces
        )
        step = _check_step(step_mm)
        origin, shape = raster.grid_geometry(uv_v[np.unique(tri)], step)
        if shape[0] * shape[1] > MAX_PIXELS:
            raise MapError(
                f"the grid would be {shape[0]} x {shape[1]} pixels: give vertex_uv_mm in mm "
                f"and a step_mm near 1 (got {step_mm})"
            )
        pixels, face, weights = raster.locate_pixels(uv_v, tri, origin, shape, step)
        lut = raster.interpolation_matrix(
            pixels, v_taxel[tri[face]], weights, shape[0] * shape[1], len(pos)
        )
        if distortion is None:
            distortion = distortion_report(pos[v_taxel] * 1e3, uv_v, tri)
        uv = raster.taxel_uv(uv_v, v_taxel, len(pos)) if taxel_uv_mm is None else taxel_uv_mm
        uv = raster.check_array(uv, "taxel_uv_mm", (len(pos), 2), float, allow_nan=True)
        origin, uv, triangles, uv_v, v_taxel, tri, pos, pixels = _readonly(
            origin, uv, v_taxel[tri], uv_v, v_taxel, tri, pos, pixels
        )
        return cls(
            step, shape, origin, uv, triangles, uv_v, v_taxel, tri, distortion, pos, pixels, lut
        )

    def __repr__(self) -> str:
        return (
            f"TactileMap({self.n_taxels} taxels, {len(self.faces)} triangles, "
            f"{self.shape[0]} x {self.shape[1]} px at {self.step_mm:g} mm)"
        )

    @classmethod
    def build(cls, layout: TaxelLayout, step_mm: float = 1.0, **kw: object) -> TactileMap:
        """Triangulate, flatten and rasterise a layout.

        kw : options of :func:`tactile.geometry.surface.triangulate` (``max_edge_factor``) and
        :func:`tactile.geometry.flatten.flatten` (``method``), routed by name.
        """
        tri_kw, flat_kw = _route_options(kw, triangulate, flatten)
        mesh = triangulate(layout.positions_m, layout.normals, **tri_kw)
        flat = flatten(layout.positions_m, mesh, **flat_kw)
        return cls.from_flat(
            layout.positions_m,
            flat.vertex_uv_mm,
            flat.vertex_taxel,
            flat.faces,
            step_mm=step_mm,
            distortion=flat.distortion,
            taxel_uv_mm=flat.taxel_uv_mm,
        )

    @property
    def n_taxels(self) -> int:
        """N, the number of taxels (columns of the look-up table)."""
        return len(self.positions_m)

    @cached_property
    def _lut32(self) -> sp.csr_matrix:
        return self.lut.astype(np.float32)

    def pixel_centers(self) -> np.ndarray:
        """uv of every pixel centre: (H, W, 2) float, mm ([..., 0] = u, [..., 1] = v)."""
        return raster.pixel_centers(self.origin_mm, self.shape, self.step_mm)

    def coverage(self) -> np.ndarray:
        """(H, W) bool — pixels whose centre lies inside the flat mesh."""
        mask = np.zeros(self.shape[0] * self.shape[1], dtype=bool)
        mask[self.pixels] = True
        return mask.reshape(self.shape)

    def interpolate(self, p: np.ndarray, *, dtype: type = np.float64) -> np.ndarray:
        """Barycentric interpolation of taxel pressures on the grid.

        p : (N,) or (B, N) float, any unit (e.g. Pa). dtype : float64, or float32 (~2x faster).

        Returns
        -------
        K : (H, W) or (B, H, W) ``dtype``, same unit as ``p``; 0 outside the mesh. A batch is
            returned as a view on pixel-major memory (frame index fastest), which avoids a
            transposition; ``np.ascontiguousarray`` it if C order matters.
        """
        p = self._check_pressures(p)
        lut = self._lut32 if np.dtype(dtype) == np.float32 else self.lut
        if p.ndim == 1:
            return (lut @ p.astype(lut.dtype, copy=False)).reshape(self.shape)
        values = lut @ np.ascontiguousarray(p.T, dtype=lut.dtype)  # (H * W, B)
        return values.T.reshape(len(p), *self.shape)

    @cached_property
    def _taxel_boxes(self) -> np.ndarray:
        """(N, 4) int64: per taxel, the first row, last row, first column and last column of
        the pixels its pressure reaches (its column of the look-up table); empty: (H, -1, W, -1)."""
        lut = self.lut.tocoo()
        (height, width), n = self.shape, self.n_taxels
        rows, cols = np.divmod(lut.row.astype(np.int64), width)
        boxes = np.tile(np.array([height, -1, width, -1], dtype=np.int64), (n, 1))
        np.minimum.at(boxes[:, 0], lut.col, rows)
        np.maximum.at(boxes[:, 1], lut.col, rows)
        np.minimum.at(boxes[:, 2], lut.col, cols)
        np.maximum.at(boxes[:, 3], lut.col, cols)
        return boxes

    def support_box(self, taxels: np.ndarray, margin_px: int = 0) -> tuple[slice, slice] | None:
        """Row and column slices of the pixels that taxels ``taxels`` (N,) bool reach, grown by
        ``margin_px`` and clipped to the grid; None when they reach no pixel."""
        boxes = self._taxel_boxes[np.asarray(taxels, bool)]
        if not len(boxes) or boxes[:, 1].max() < 0:
            return None
        top, left = boxes[:, 0].min(), boxes[:, 2].min()
        bottom, right = boxes[:, 1].max(), boxes[:, 3].max()
        height, width = self.shape
        return (
            slice(max(top - margin_px, 0), min(bottom + margin_px + 1, height)),
            slice(max(left - margin_px, 0), min(right + margin_px + 1, width)),
        )

    @cached_property
    def _lut_rows(self) -> tuple[np.ndarray, np.ndarray]:
        """The look-up table as (H * W, k) taxel indices (int32) and weights (float64), each
        pixel's entries in the table's order, padded with weight 0 (k = most entries per pixel,
        3 inside a triangle)."""
        lut = self.lut
        counts = np.diff(lut.indptr)
        k = max(int(counts.max(initial=0)), 1)
        slot = np.arange(lut.nnz) - np.repeat(lut.indptr[:-1], counts)
        row = np.repeat(np.arange(lut.shape[0]), counts)
        index = np.zeros((lut.shape[0], k), dtype=np.int32)
        weight = np.zeros((lut.shape[0], k), dtype=np.float64)
        index[row, slot], weight[row, slot] = lut.indices, lut.data
        return index, weight

    def interpolate_box(self, p: np.ndarray, rows: slice, cols: slice) -> np.ndarray:
        """``self.interpolate(p)[..., rows, cols]``, computed on those pixels only: each pixel's
        weighted taxels summed in the look-up table's order, so the same floats: (h, w) or
        (B, h, w) float64 (a batch as a view on pixel-major memory, as `interpolate`)."""
        height, width = self.shape
        r, c = range(*rows.indices(height)), range(*cols.indices(width))
        if np.ndim(p) == 1:  # gathered: 3x faster than the table's rows for one frame
            index, weight = (
                a.reshape(height, width, -1)[r.start : r.stop, c.start : c.stop]
                for a in self._lut_rows
            )
            p = np.asarray(p, dtype=np.float64)
            values = weight[..., 0] * p[index[..., 0]]
            for j in range(1, index.shape[-1]):
                values += weight[..., j] * p[index[..., j]]
            return values
        flat = (np.arange(r.start, r.stop)[:, None] * width + np.arange(c.start, c.stop)).ravel()
        values = self.lut[flat] @ np.ascontiguousarray(p.T, dtype=np.float64)  # faster batched
        return values.T.reshape(len(p), len(r), len(c))

    def image(self, p: np.ndarray, *, erode_px: int = 2, dilate_px: int = 4) -> np.ndarray:
        """The paper's tactile image: grey levels, erosion then dilation with disk footprints.

        p : (N,) or (B, N) float pressures (>= 0). erode_px, dilate_px : int, pixels (0 skips).

        Returns
        -------
        image : (H, W) or (B, H, W) uint8 — floor(255 K / max p) per frame then the morphology;
            an all-zero (or non-positive) frame gives an all-zero image.
        """
        p = self._check_pressures(p)
        if p.ndim == 1:
            return self._image_one(p, erode_px, dilate_px)
        grey = raster.grey_levels(self.interpolate(p), p.max(axis=-1))
        grey = np.ascontiguousarray(grey)
        if grey.ndim == 2 or len(grey) == 0:
            return erode_dilate(grey, erode_px, dilate_px)
        return np.stack([erode_dilate(g, erode_px, dilate_px) for g in grey])

    def _image_one(self, p: np.ndarray, erode_px: int, dilate_px: int) -> np.ndarray:
        """One frame's image, made on the box of the pixels its pressed taxels reach, grown by
        both radii and one pixel: outside the box the image is 0, and inside it the padding the
        morphology reflects at an inner edge is 0 as on the whole grid, so the box holds the
        whole-grid result (tests/tactile/test_tactile_map.py compares the two)."""
        for radius in (erode_px, dilate_px):
            if int(radius) != radius or radius < 0:
                raise MapError(
                    f"disk radius must be a non-negative integer of pixels, got {radius!r}"
                )
        out = np.zeros(self.shape, dtype=np.uint8)
        box = self.support_box(p > 0, int(erode_px) + int(dilate_px) + 1)
        if box is None:
            return out
        grey = raster.grey_levels(self.interpolate_box(p, *box), p.max())
        out[box] = erode_dilate(np.ascontiguousarray(grey), erode_px, dilate_px)
        return out

    def label_image(
        self, p: np.ndarray, labels: np.ndarray, *, erode_px: int = 2, dilate_px: int = 4
    ) -> np.ndarray:
        """Class of every pixel, consistent with :meth:`image`
        (:func:`tactile.images.labels.label_image`).

        p : (N,) float pressures. labels : (N,) int class per taxel (0..6).

        Returns
        -------
        classes : (H, W) uint8 — 0 where the tactile image is 0.
        """
        return label_image(self, p, labels, erode_px=erode_px, dilate_px=dilate_px)

    def _check_pressures(self, p: np.ndarray) -> np.ndarray:
        p = np.asarray(p)
        if p.ndim not in (1, 2) or p.shape[-1] != self.n_taxels:
            raise MapError(
                f"pressures must have shape ({self.n_taxels},) or (B, {self.n_taxels}) for this "
                f"map of {self.n_taxels} taxels, got {p.shape}"
            )
        if not np.issubdtype(p.dtype, np.number) or np.iscomplexobj(p):
            raise MapError(f"pressures must be real numbers, got dtype {p.dtype}")
        bad = ~np.isfinite(p)
        if bad.any():
            frame, taxel = divmod(int(np.flatnonzero(bad)[0]), self.n_taxels)
            where = f"taxel {taxel}" + (f" of frame {frame}" if p.ndim == 2 else "")
            value = p.ravel()[bad.ravel()][0]
            raise MapError(f"pressure of {where} is {value}; give finite pressures")
        return p

    def save(self, path: str | PathLike[str]) -> None:
        """Write the map to ``path`` (.npz): geometry, distortion; the table is rebuilt on load."""
        extra = {f"distortion_{k}": getattr(self.distortion, k) for k in _DISTORTION}
        np.savez_compressed(
            path,
            format=FORMAT,
            step_mm=self.step_mm,
            positions_m=self.positions_m,
            uv=self.uv,
            vertex_uv_mm=self.vertex_uv_mm,
            vertex_taxel=self.vertex_taxel,
            faces=self.faces,
            distortion_n_flipped=self.distortion.n_flipped,
            **extra,
        )

    @classmethod
    def load(cls, path: str | PathLike[str]) -> TactileMap:
        """Read a map written by :meth:`save` (.npz)."""
        try:
            with np.load(path, allow_pickle=False) as f:
                data = {k: f[k] for k in f.files}
        except (OSError, ValueError) as err:
            raise MapError(
                f"cannot read tactile map {path}: {err}; write it with TactileMap.save"
            ) from err
        missing = sorted(set(_KEYS) - set(data))
        if missing or str(data["format"]) != FORMAT:
            raise MapError(
                f"{path} is not a tactile map ({FORMAT}): missing {missing or 'the format tag'}; "
                "rebuild it with TactileMap.build(...).save(path)"
            )
        report = DistortionReport(
            *(data[f"distortion_{k}"] for k in _DISTORTION), int(data["distortion_n_flipped"])
        )
        return cls.from_flat(
            data["positions_m"],
            data["vertex_uv_mm"],
            data["vertex_taxel"],
            data["faces"],
            step_mm=float(data["step_mm"]),
            distortion=report,
            taxel_uv_mm=data["uv"],
        )


def _route_options(kw: dict, *functions: object) -> list[dict]:
    """Split keyword options between functions by their keyword-only parameter names."""
    names = [
        {n for n, p in inspect.signature(f).parameters.items() if p.kind is p.KEYWORD_ONLY}
        for f in functions
    ]
    unknown = sorted(set(kw) - set().union(*names))
    if unknown:
        known = ", ".join(sorted(set().union(*names)))
        raise MapError(f"unknown map option(s) {unknown}; known options: {known}")
    return [{k: v for k, v in kw.items() if k in n} for n in names]
