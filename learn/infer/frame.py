"""The operators of the fast frame path, built once per map and network: a taxel frame to its
tactile image on the box the touch covers, that box straight to the network's input size, and
the network's labels back to the taxels without the full-size label image.

    pix = ImageOps.build(tmap)
    box = pix.fill(p, image)           # image (H, W) uint8 = tmap.image(p); box: rows, columns
    ops = InputOps.build(tmap, input_size=(68, 100), canvas=None)
    x = ops.resize(image, box, out)    # (h, w) float32 = learn.inputs.net_input(image / 255, ...)
    labels = TaxelVotes.build(tmap, ops).labels(net_labels, image)   # =
    tactile.images.labels.backproject

Each operator is the reference's own (`tactile.images.resize`, `learn.inputs`,
`tactile.images.labels`), so it computes the same bytes: the anti-aliased resize as the exact
float64 operators of `tactile.images.resize.resize_grey` (``rows @ grey @ cols.T / 255``, whose sums
are exact in any order) with the canvas folded in, the nearest-neighbour resizes as index arrays,
the back-projection as a vote over each taxel's 2-pixel neighbourhood.
Only the box of the map a frame presses is touched: the look-up table's rows, the erosion and
dilation (exact there: the box keeps a margin wider than both disks) and the resize's columns.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from learn.inputs import labels_on_map
from tactile.images.labels import N_CLASSES, neighbourhood_matrix
from tactile.images.morphology import erode_dilate
from tactile.images.raster import grey_levels
from tactile.images.resize import fit_canvas, resize_labels, resize_operator
from tactile.images.tactile_map import TactileMap

Box = tuple[int, int, int, int]  # rows r0:r1, columns c0:c1 of the map grid, pixels


@dataclass(frozen=True)
class ImageOps:
    """The look-up table as dense (K, H, W) planes (``taxels`` int32, ``weights`` float64, in
    the table's own order, zero-padded) beside the map they come from."""

    tmap: TactileMap
    taxels: np.ndarray
    weights: np.ndarray
    erode_px: int = 2
    dilate_px: int = 4

    @classmethod
    def build(cls, tmap: TactileMap, erode_px: int = 2, dilate_px: int = 4) -> ImageOps:
        lut, (height, width) = tmap.lut, tmap.shape
        per_row = np.diff(lut.indptr)
        row = np.repeat(np.arange(len(per_row)), per_row)
        slot = np.arange(lut.nnz) - lut.indptr[row]
        k = max(int(per_row.max()), 1)
        taxels = np.zeros((k, height * width), np.int32)
        weights = np.zeros((k, height * width), np.float64)
        taxels[slot, row], weights[slot, row] = lut.indices, lut.data
        shape = (k, height, width)
        return cls(tmap, taxels.reshape(shape), weights.reshape(shape), erode_px, dilate_px)

    def box(self, p: np.ndarray) -> Box | None:
        """The map box a frame ``p`` (N,) Pa can make non-zero (`TactileMap.support_box`), grown
        by a margin wider than the erosion and dilation disks; None when it lights no pixel."""
        box = self.tmap.support_box(p > 0, self.erode_px + self.dilate_px + 1)
        return None if box is None else (box[0].start, box[0].stop, box[1].start, box[1].stop)

    def fill(self, p: np.ndarray, image: np.ndarray, last: Box | None = None) -> Box | None:
        """Write ``tmap.image(p)`` into ``image`` (H, W) uint8, zero but on ``last`` (the box
        of the frame written there before, cleared first); returns this frame's box."""
        if last is not None:
            image[last[0] : last[1], last[2] : last[3]] = 0
        box = self.box(p)
        if box is None:
            return None
        r0, r1, c0, c1 = box
        taxels, weights = self.taxels[:, r0:r1, c0:c1], self.weights[:, r0:r1, c0:c1]
        values = weights[0] * p.take(taxels[0])
        for j in range(1, len(taxels)):  # the table's order of summation, as ``lut @ p``
            values += weights[j] * p.take(taxels[j])
        grey = grey_levels(values, np.float64(p.max()))
        image[r0:r1, c0:c1] = erode_dilate(grey, self.erode_px, self.dilate_px)
        return box


def _axis_operator(n_in: int, n_canvas: int | None, n_out: int) -> np.ndarray:
    """(n_out, n_in) float64: the canvas fit then the anti-aliased resize along one axis, the
    weights those of `tactile.images.resize.resize_operator` (a fit selects one of them or none)."""
    fit = np.eye(n_in) if n_canvas is None else fit_canvas(np.eye(n_in), (n_canvas, n_in))
    return resize_operator(fit.shape[0], n_out) @ fit


def _reached(op: np.ndarray) -> np.ndarray:
    """(n_in, 2) int: the output rows ``lo:hi`` each input row of ``op`` (n_out, n_in) reaches
    (``n_out:0`` for none)."""
    nz = op != 0
    lo = np.where(nz.any(0), nz.argmax(0), len(op))
    hi = np.where(nz.any(0), len(op) - nz[::-1].argmax(0), 0)
    return np.stack([lo, hi], axis=1)


@dataclass(frozen=True)
class InputOps:
    """How one network sees a map image: ``rows`` (h, H), ``cols`` (w, W) float64 tensors
    (multiplied by torch, on its threads, not numpy's BLAS pool) and the output rows / columns
    each map row / column reaches (``row_reach``, ``col_reach``);
    ``support`` (h, w) int64, the map pixel (flat index + 1, 0 off the map) whose pressure
    keeps a segmenter's input pixel on; ``on_canvas`` (H, W) bool, the map pixels the canvas
    keeps; ``back`` (H * W,) int64, the input pixel (flat index + 1, 0 off the canvas) each
    map pixel takes its label from."""

    rows: torch.Tensor
    cols: torch.Tensor
    row_reach: np.ndarray
    col_reach: np.ndarray
    support: np.ndarray
    on_canvas: np.ndarray
    back: np.ndarray

    @classmethod
    def build(
        cls, tmap: TactileMap, input_size: tuple[int, int], canvas: tuple[int, int] | None
    ) -> InputOps:
        (height, width), (h, w) = tmap.shape, input_size
        rows = _axis_operator(height, None if canvas is None else canvas[0], h)
        cols = _axis_operator(width, None if canvas is None else canvas[1], w)
        index = np.arange(1, height * width + 1).reshape(height, width)
        fitted = index if canvas is None else fit_canvas(index, canvas)
        on_canvas = np.zeros(height * width, bool)
        on_canvas[fitted[fitted > 0] - 1] = True
        back = labels_on_map(np.arange(1, h * w + 1).reshape(h, w), tmap.shape, canvas)
        return cls(
            torch.from_numpy(rows),
            torch.from_numpy(cols),
            _reached(rows),
            _reached(cols),
            resize_labels(fitted, input_size),
            on_canvas.reshape(height, width),
            back.ravel(),
        )

    def resize(self, image: np.ndarray, box: Box | None, out: np.ndarray) -> np.ndarray:
        """``out`` (h, w) float32 := the anti-aliased resize of ``image`` (H, W) uint8, / 255,
        zero outside ``box``: `learn.inputs.net_input` of a classifier, byte for byte."""
        out[:] = 0
        if box is None:
            return out
        r0, r1, c0, c1 = box
        o0, o1 = self.row_reach[r0:r1, 0].min(), self.row_reach[r0:r1, 1].max()
        q0, q1 = self.col_reach[c0:c1, 0].min(), self.col_reach[c0:c1, 1].max()
        if o1 <= o0 or q1 <= q0:
            return out  # the touch is off the canvas
        grey = torch.from_numpy(image[r0:r1, c0:c1].astype(np.float64))
        part = self.rows[o0:o1, r0:r1] @ grey @ self.cols[q0:q1, c0:c1].T
        out[o0:o1, q0:q1] = (part / 255.0).numpy()
        return out

    def keep_support(
        self, resized: np.ndarray, image_ext: np.ndarray, box: Box | None, out: np.ndarray
    ) -> np.ndarray:
        """``out`` (h, w) float32 := a segmenter's input from ``resized`` (`resize`): zero off
        the nearest-neighbour support of the pressed pixels, at least the smallest pressed
        pixel on the canvas inside it (`tactile.images.resize.resize_image` ``keep_support``).
        ``image_ext`` (H * W + 1,) uint8: a 0, then the map image's pixels."""
        out[:] = 0
        if box is None:
            return out
        r0, r1, c0, c1 = box
        crop = image_ext[1:].reshape(self.on_canvas.shape)[r0:r1, c0:c1]
        pressed = crop[(crop > 0) & self.on_canvas[r0:r1, c0:c1]]
        if not len(pressed):
            return out
        low = np.float32(pressed.min()) / np.float32(255.0)
        kept = image_ext[self.support] > 0
        np.copyto(out, np.maximum(resized, low), where=kept)
        return out


@dataclass(frozen=True)
class TaxelVotes:
    """`tactile.images.labels.backproject` as a vote: each entry (``taxel``, map ``pixel``: flat
    index + 1) of the taxels' 2-pixel neighbourhoods, in the order of the pixels, with the network
    input pixel the map pixel takes its label from (``source``: flat index + 1, 0 off the
    canvas); ``width``: the map's, pixels."""

    taxel: np.ndarray
    pixel: np.ndarray
    source: np.ndarray
    n_taxels: int
    width: int

    @classmethod
    def build(cls, tmap: TactileMap, ops: InputOps) -> TaxelVotes:
        near = neighbourhood_matrix(tmap, 2.0 * tmap.step_mm).tocoo()
        order = np.argsort(near.col, kind="stable")
        taxel, pixel = near.row[order].astype(np.int64), near.col[order].astype(np.int64)
        return cls(taxel, pixel + 1, ops.back[pixel], tmap.n_taxels, tmap.shape[1])

    def labels(self, labels_ext: np.ndarray, image_ext: np.ndarray, box: Box | None) -> np.ndarray:
        """(N,) uint8: per taxel, the most frequent hand part (ties: the smaller id) among the
        pressed map pixels near it, each labelled by its network pixel; 0 where there is none.
        ``labels_ext`` (h * w + 1,) and ``image_ext`` (H * W + 1,): a 0, then the network's
        labels and the map image (0 outside ``box``), flat."""
        if box is None:
            return np.zeros(self.n_taxels, np.uint8)
        r0, r1, c0, c1 = box
        first, last = r0 * self.width + c0 + 1, (r1 - 1) * self.width + c1 + 1
        lo, hi = np.searchsorted(self.pixel, (first, last))
        label = labels_ext[self.source[lo:hi]]
        vote = (image_ext[self.pixel[lo:hi]] > 0) & (label > 0)
        keys = self.taxel[lo:hi][vote] * N_CLASSES + label[vote]
        counts = np.bincount(keys, minlength=self.n_taxels * N_CLASSES)
        counts = counts.reshape(self.n_taxels, N_CLASSES)[:, 1:]
        best = counts.argmax(axis=1) + 1
        return np.where(counts.max(axis=1) > 0, best, 0).astype(np.uint8)
