"""A model scored on tensors: the confusion matrix, Long et al.'s scores and the mean loss. The
loop validates with it every epoch; ``handskin evaluate`` scores test splits with it.

    res = evaluate_tensors(model, data.test, num_classes=2)   # res.metrics, res.cm, res.percent
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from learn import metrics as M
from learn.data.load import TensorData
from learn.inputs import unpressed_as_background
from learn.numerics import flushing
from learn.train.device import device_of
from tactile.images.labels import IGNORE


@dataclass
class EvalResult:
    """Confusion matrix ``cm`` (C, C) int64 (rows true), scores (fractions), mean loss, and the
    predicted classes ((S,) or (S, h, w) int64) when asked for. A class-and-parts network
    (`learn.models.compact.HandParts`) also has ``class_cm`` (2, 2): ``cm`` is then its parts'
    on the hand images."""

    cm: torch.Tensor
    metrics: dict[str, float]
    loss: float
    predictions: torch.Tensor | None = None
    class_cm: torch.Tensor | None = None

    @property
    def percent(self) -> torch.Tensor:
        """(C, C) float64: rows as percentages of the true class (the paper's tables)."""
        return M.percent_by_true_class(self.cm)


def scores(cm: np.ndarray | torch.Tensor) -> dict[str, float]:
    """Accuracy, mean class accuracy and Long et al.'s IoU scores of a confusion matrix,
    fractions."""
    cm = torch.as_tensor(np.asarray(cm))
    return {"accuracy": M.accuracy(cm), **M.segmentation_scores(cm)}


def as_float(out):
    """A network's output as float32 on the CPU: a tensor, or a tuple of them (class and parts)."""
    if isinstance(out, tuple):
        return tuple(o.float().cpu() for o in out)
    return out.float().cpu()


def hand_targets(y: torch.Tensor) -> torch.Tensor:
    """(S,) int64 classes of a class-and-parts target (S, h, w): a non-hand is all `IGNORE`."""
    return (y != IGNORE).flatten(1).any(1).long()


def logits_of(model: nn.Module, x: torch.Tensor, batch_size: int = 64):
    """Float32 logits, on the CPU, of ``x`` (S, 1, h, w) in eval mode under ``torch.no_grad``,
    batch by batch on the model's device (a tuple of them for a class-and-parts network)."""
    model.eval()
    dev = device_of(model)
    with torch.no_grad():
        out = [as_float(model(x[i : i + batch_size].to(dev))) for i in range(0, len(x), batch_size)]
    if isinstance(out[0], tuple):
        return tuple(torch.cat(parts) for parts in zip(*out, strict=True))
    return torch.cat(out)


@flushing()
def evaluate_tensors(
    model: nn.Module,
    data: TensorData,
    num_classes: int,
    batch_size: int = 64,
    loss_fn: nn.Module | None = None,
    keep_predictions: bool = False,
) -> EvalResult:
    """Scores of ``model`` on ``data`` (x (S, 1, h, w), y (S,) or (S, h, w)), left in eval mode.

    Segmentation predictions are background where the input is 0
    (`learn.inputs.unpressed_as_background`). ``loss`` is the mean of ``loss_fn`` (NaN without
    one); ``keep_predictions`` also returns the predicted classes.
    """
    cms, class_cms, losses, preds = [], [], [], []
    loss_dev = None if loss_fn is None else device_of(loss_fn)  # where its class weights live
    for i in range(0, len(data.y), batch_size):
        x, y = data.x[i : i + batch_size], data.y[i : i + batch_size]
        out = logits_of(model, x, batch_size)
        if isinstance(out, tuple):  # class and parts: the class of every image
            class_cms.append(M.confusion_matrix(hand_targets(y), out[0].argmax(1), 2))
        parts = out[1] if isinstance(out, tuple) else out
        pred = parts.argmax(1) if y.ndim == 1 else unpressed_as_background(parts.argmax(1), x)
        cms.append(M.confusion_matrix(y, pred, num_classes, ignore_index=IGNORE))
        if keep_predictions:
            preds.append(pred)
        if loss_fn is not None:
            with torch.no_grad():
                dev_out = tuple(o.to(loss_dev) for o in out) if class_cms else out.to(loss_dev)
                losses.append(float(loss_fn(dev_out, y.to(loss_dev))) * len(y))
    cm = torch.stack(cms).sum(0)
    loss = sum(losses) / len(data.y) if losses else float("nan")
    metrics, class_cm = scores(cm), None
    if class_cms:
        class_cm = torch.stack(class_cms).sum(0)
        metrics |= {"class_accuracy": M.accuracy(class_cm)}
        metrics["class_and_parts"] = (metrics["class_accuracy"] + metrics["mean_iou"]) / 2
    return EvalResult(cm, metrics, loss, torch.cat(preds) if preds else None, class_cm)
