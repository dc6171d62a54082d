"""Metrics as pure functions of label tensors or of a confusion matrix.

The confusion matrix ``cm`` is ``(C, C)`` int64 with ``cm[i, j]`` = samples (or pixels) of true
class ``i`` predicted as ``j`` (Long et al.'s ``n_ij``). Segmentation scores follow Long,
Shelhamer & Darrell (CVPR 2015, Sec. 5), with classes absent from the ground truth
(``t_i = Σ_j n_ij = 0``) skipped in the means.
"""

from __future__ import annotations

import numpy as np
import torch

from tactile.errors import DataError

ArrayLike = np.ndarray | torch.Tensor


def confusion_matrix(
    target: ArrayLike, pred: ArrayLike, num_classes: int, ignore_index: int | None = None
) -> torch.Tensor:
    """``(C, C)`` int64 counts of (true, predicted) pairs; rows true class, columns predicted.

    target, pred : any equal shapes of integer class ids; ``ignore_index`` pixels are dropped.
    """
    t, p = torch.as_tensor(target), torch.as_tensor(pred)
    if t.shape != p.shape:
        raise DataError(f"confusion_matrix: target {tuple(t.shape)} vs pred {tuple(p.shape)}")
    t, p = t.reshape(-1).long().cpu(), p.reshape(-1).long().cpu()
    if ignore_index is not None:
        keep = t != ignore_index
        t, p = t[keep], p[keep]
    if t.numel() and (min(t.min(), p.min()) < 0 or max(t.max(), p.max()) >= num_classes):
        raise DataError(f"confusion_matrix: class ids must lie in 0..{num_classes - 1}")
    flat = torch.bincount(t * num_classes + p, minlength=num_classes * num_classes)
    return flat.reshape(num_classes, num_classes)


def _diag_and_totals(cm: ArrayLike) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """``n_ii``, ``t_i = Σ_j n_ij`` (true) and ``Σ_j n_ji`` (predicted), as float64."""
    cm = torch.as_tensor(cm, dtype=torch.float64)
    return cm.diagonal(), cm.sum(1), cm.sum(0)


def accuracy(cm: ArrayLike) -> float:
    """Overall accuracy ``Σ n_ii / Σ n_ij`` (= pixel accuracy for segmentation); NaN if empty."""
    n_ii, t_i, _ = _diag_and_totals(cm)
    return float(n_ii.sum() / t_i.sum()) if t_i.sum() > 0 else float("nan")


pixel_accuracy = accuracy


def percent_by_true_class(cm: ArrayLike) -> torch.Tensor:
    """``(C, C)`` float64: each row as percentages of its true class (the paper's Tables 4–10).

    Rows of classes absent from the ground truth are NaN.
    """
    cm = torch.as_tensor(cm, dtype=torch.float64)
    t_i = cm.sum(1, keepdim=True)
    return torch.where(t_i > 0, 100.0 * cm / t_i.clamp_min(1), torch.nan)


def class_accuracies(cm: ArrayLike) -> torch.Tensor:
    """``(C,)`` float64 per-class accuracy (recall) ``n_ii / t_i``; NaN for absent classes."""
    n_ii, t_i, _ = _diag_and_totals(cm)
    return torch.where(t_i > 0, n_ii / t_i.clamp_min(1), torch.nan)


def class_ious(cm: ArrayLike) -> torch.Tensor:
    """``(C,)`` float64 IoU ``n_ii / (t_i + Σ_j n_ji − n_ii)``; NaN for absent true classes."""
    n_ii, t_i, p_i = _diag_and_totals(cm)
    return torch.where(t_i > 0, n_ii / (t_i + p_i - n_ii).clamp_min(1), torch.nan)


def mean_class_accuracy(cm: ArrayLike) -> float:
    """Long et al.'s mean accuracy ``(1/n_cl) Σ_i n_ii / t_i`` over classes present (t_i > 0)."""
    return float(class_accuracies(cm).nanmean())


def mean_iou(cm: ArrayLike) -> float:
    """Long et al.'s mean IU ``(1/n_cl) Σ_i n_ii / (t_i + Σ_j n_ji − n_ii)``, present classes."""
    return float(class_ious(cm).nanmean())


def frequency_weighted_iou(cm: ArrayLike) -> float:
    """Long et al.'s ``(Σ_k t_k)^-1 Σ_i t_i n_ii / (t_i + Σ_j n_ji − n_ii)``."""
    _, t_i, _ = _diag_and_totals(cm)
    if t_i.sum() == 0:
        return float("nan")
    return float((t_i * class_ious(cm).nan_to_num(0.0)).sum() / t_i.sum())


def without_true_class(cm: ArrayLike, c: int = 0) -> torch.Tensor:
    """``cm`` with true class ``c``'s row zeroed: scores over the other classes' pixels only.

    Class ``c`` is then absent from the ground truth, so Long et al.'s means skip it, while the
    pixels of other classes predicted as ``c`` (column ``c``) stay errors. With ``c = 0`` this
    scores a segmentation on the hand's pixels alone, as a labelling that leaves background
    unlabelled (ignored) would: ``(C, C)`` int64.
    """
    cm = torch.as_tensor(np.asarray(cm), dtype=torch.int64).clone()
    if not 0 <= c < cm.shape[0]:
        raise DataError(f"class {c} is not in 0..{cm.shape[0] - 1}")
    cm[c] = 0
    return cm


def segmentation_scores(cm: ArrayLike) -> dict[str, float]:
    """The four scores of Long et al. (fractions in [0, 1]) from one confusion matrix."""
    return {
        "pixel_accuracy": pixel_accuracy(cm),
        "mean_accuracy": mean_class_accuracy(cm),
        "mean_iou": mean_iou(cm),
        "fw_iou": frequency_weighted_iou(cm),
    }
