"""A segmenter's test images by their own mIoU, lowest first: where it fails. The predicted
label maps of the worst few are packed into the JSON row (`pack_labels`) so the report's
picture of them (`learn.error_sheets`) can be drawn again from the JSON alone.
"""

from __future__ import annotations

import base64
import zlib
from collections.abc import Sequence

import numpy as np

from learn.breakdown import plain_scalar
from learn.significance import batched_mean_iou, per_image_confusion

#: A segmenter's worst test images kept in its report row, and how many of them (the first)
#: carry their predicted label maps for the report's picture.
N_WORST_KEPT, N_WORST_MAPS = 50, 9


def worst_segmentations(
    pred: np.ndarray,
    truth: np.ndarray,
    indices: Sequence[int],
    num_classes: int,
    about: dict[str, Sequence] | None = None,
    cms: np.ndarray | None = None,
) -> tuple[list[dict[str, object]], np.ndarray]:
    """Every test image scored on its own, lowest mIoU first (ties by pixel accuracy, then
    test order): where a segmenter fails. pred, truth : (S, h, w) int class ids; indices :
    (S,) dataset sample indices; ``about`` : named (S,) sequences copied into each record;
    ``cms`` : the images' (S, C, C) confusion matrices when the caller has them already
    (`learn.significance.per_image_confusion`).

    Each image's mIoU and pixel accuracy follow Long et al. on its own confusion matrix:
    classes absent from its ground truth are skipped in the mean, so a finger painted where
    none touches costs the IoU of the class it covers. Returns the records
    ``{"index", "mean_iou", "pixel_accuracy", **about}`` (scores as fractions 0..1) and the
    (S,) order of test positions they follow.
    """
    pred, truth = np.asarray(pred), np.asarray(truth)
    if pred.shape != truth.shape or pred.ndim != 3:
        raise ValueError(f"pred {pred.shape} and truth {truth.shape} must be equal (S, h, w)")
    s = len(truth)
    cm = per_image_confusion(pred, truth, num_classes) if cms is None else cms
    miou = batched_mean_iou(cm)
    acc = np.diagonal(cm, axis1=1, axis2=2).sum(1) / cm.sum((1, 2))
    order = np.lexsort((np.arange(s), acc, miou))
    about = about or {}
    records = [
        {
            "index": int(indices[k]),
            "mean_iou": float(miou[k]),
            "pixel_accuracy": float(acc[k]),
            **{name: plain_scalar(values[k]) for name, values in about.items()},
        }
        for k in order
    ]
    return records, order


def pack_labels(labels: np.ndarray) -> dict[str, object]:
    """(N, h, w) class ids (0..255) as a JSON-ready dict: shape and zlib-compressed base64
    bytes (a print's label map is mostly background, so a few kB). `unpack_labels` inverts."""
    labels = np.asarray(labels)
    if labels.size and (labels.min() < 0 or labels.max() > 255):
        raise ValueError("pack_labels: class ids must lie in 0..255")
    raw = zlib.compress(np.ascontiguousarray(labels, dtype=np.uint8).tobytes(), 9)
    return {"shape": list(labels.shape), "zlib_base64": base64.b64encode(raw).decode("ascii")}


def unpack_labels(packed: dict[str, object]) -> np.ndarray:
    """The uint8 array of shape ``packed["shape"]`` that `pack_labels` stored."""
    raw = zlib.decompress(base64.b64decode(str(packed["zlib_base64"])))
    return np.frombuffer(raw, np.uint8).reshape([int(n) for n in packed["shape"]]).copy()
