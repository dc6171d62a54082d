"""Segmentation and classification losses: median-frequency weights, weighted CE, soft Dice.

The paper found weighted cross-entropy best for SegNet and Dice for FCN; both are here.
Logits come in, softmax is applied inside the losses.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
import torch
from torch import nn

from learn.config import LOSSES
from tactile.errors import ConfigError, DataError
from tactile.images.labels import IGNORE


def class_pixel_counts(
    labels: Iterable[np.ndarray | torch.Tensor], num_classes: int
) -> tuple[np.ndarray, np.ndarray]:
    """Pixel counts for median-frequency balancing, over label images ``(H, W)`` (or batches).

    Returns ``(class_pixels, image_pixels)``, both ``(num_classes,)`` int64: the pixels of each
    class, and the total pixels of the images in which that class appears (Eigen & Fergus);
    `IGNORE` pixels (box-derived labels that no box names) count in neither.
    """
    class_pixels = np.zeros(num_classes, np.int64)
    image_pixels = np.zeros(num_classes, np.int64)
    for label in labels:
        arr = np.asarray(label)
        batch = arr.reshape(-1, arr.shape[-2] * arr.shape[-1]) if arr.ndim >= 2 else arr[None]
        kept = batch[batch != IGNORE]
        if kept.size and (kept.min() < 0 or kept.max() >= num_classes):
            raise DataError(f"label ids must lie in 0..{num_classes - 1}; got {kept.max()}")
        for img in batch:
            img = img[img != IGNORE]
            counts = np.bincount(img, minlength=num_classes)
            class_pixels += counts
            image_pixels += np.where(counts > 0, img.size, 0)
    return class_pixels, image_pixels


def median_frequency_weights(class_pixels: np.ndarray, image_pixels: np.ndarray) -> np.ndarray:
    """Median-frequency class weights ``median(freq) / freq(c)`` (Eigen & Fergus, 2015).

    ``freq(c) = class_pixels[c] / image_pixels[c]`` is the class's share of the pixels of the
    images where it is present. Classes never seen get weight 1 (they never appear as a target,
    so the value does not matter); the median is over the seen classes. Returns ``(C,)`` float64.
    """
    class_pixels = np.asarray(class_pixels, np.float64)
    image_pixels = np.asarray(image_pixels, np.float64)
    seen = class_pixels > 0
    if not seen.any():
        raise ConfigError("median-frequency weights: no labelled pixels; pass non-empty labels")
    freq = np.divide(class_pixels, image_pixels, out=np.zeros_like(class_pixels), where=seen)
    weights = np.ones_like(freq)
    weights[seen] = np.median(freq[seen]) / freq[seen]
    return weights


def weighted_cross_entropy(
    logits: torch.Tensor,
    target: torch.Tensor,
    weights: torch.Tensor | Sequence[float] | None = None,
    ignore_index: int = IGNORE,
) -> torch.Tensor:
    """Class-weighted cross-entropy: ``Σ w[y]·(−log softmax[y]) / Σ w[y]`` (scalar), over the
    targets that are not ``ignore_index``.

    logits : ``(B, C)`` or ``(B, C, H, W)``; target : ``(B,)`` or ``(B, H, W)`` int64 class ids.
    """
    w = None if weights is None else torch.as_tensor(weights, dtype=logits.dtype).to(logits.device)
    return nn.functional.cross_entropy(logits, target, weight=w, ignore_index=ignore_index)


def soft_dice_loss(
    logits: torch.Tensor,
    target: torch.Tensor,
    *,
    generalized: bool = False,
    eps: float = 1.0,
) -> torch.Tensor:
    """Soft Dice loss ``1 − mean_c (2 Σ p·g + ε) / (Σ p + Σ g + ε)`` (scalar).

    logits : ``(B, C, H, W)``; target : ``(B, H, W)`` int64. Sums run over the batch and pixels
    per class; ``p`` is the softmax, ``g`` the one-hot target; ``ε`` (pixels) smooths empty
    classes (absent in both prediction and target count as a perfect match). ``generalized``
    weights classes by ``1 / (Σ g)²`` as Sudre et al. (2017) do (MATLAB's Dice layer). `IGNORE`
    pixels count in no sum.
    """
    valid = (target != IGNORE).unsqueeze(1)
    probs = logits.softmax(dim=1) * valid
    onehot = nn.functional.one_hot(target.where(valid[:, 0], 0), logits.shape[1])
    onehot = onehot.movedim(-1, 1).to(probs.dtype) * valid
    dims = (0, *range(2, logits.ndim))
    inter = (probs * onehot).sum(dims)
    total = probs.sum(dims) + onehot.sum(dims)
    if generalized:
        w = 1.0 / onehot.sum(dims).clamp_min(1.0) ** 2
        return 1.0 - (2 * (w * inter).sum() + eps) / ((w * total).sum() + eps)
    return 1.0 - ((2 * inter + eps) / (total + eps)).mean()


class SegmentationLoss(nn.Module):
    """A loss module by name (`learn.config.LOSSES`): ``"ce"``, ``"weighted_ce"``, ``"dice"``,
    ``"generalized_dice"`` or ``"ce_dice"``.

    ``forward(logits (B, C, ...), target (B, ...)) → scalar``. ``"weighted_ce"`` needs the
    ``(C,)`` class weights (e.g. :func:`class_weights`). ``"ce_dice"`` is plain cross-entropy
    plus soft Dice with equal weights (as nnU-Net trains): the CE term gives every pixel a
    gradient from the start, where Dice alone can sit at background-only.
    """

    def __init__(self, name: str = "ce", weights: Sequence[float] | np.ndarray | None = None):
        super().__init__()
        if name not in LOSSES:
            raise ConfigError(f"unknown loss {name!r}; choose one of: {', '.join(LOSSES)}")
        if name == "weighted_ce" and weights is None:
            raise ConfigError("loss 'weighted_ce' needs class weights (class_weights)")
        self.name = name
        w = None if weights is None or name != "weighted_ce" else torch.as_tensor(weights).float()
        self.register_buffer("weights", w)

    def forward(self, logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        """Scalar loss of ``logits (B, C, ...)`` against ``target (B, ...)`` int64."""
        if self.name == "ce_dice":
            return weighted_cross_entropy(logits, target) + soft_dice_loss(logits, target)
        if self.name.endswith("dice"):
            return soft_dice_loss(logits, target, generalized=self.name == "generalized_dice")
        return weighted_cross_entropy(logits, target, self.weights)


class BothLoss(nn.Module):
    """The loss of a class-and-parts network (`learn.models.compact.HandParts`): cross-entropy of
    its hand / non-hand logits plus its parts' `SegmentationLoss` ``name`` (``weights``: their
    class weights). ``forward((class (B, 2), parts (B, C, h, w)), target (B, h, w))``: the
    target is a hand's label image, a non-hand's all `IGNORE` (so the parts learn from hands
    only, as the paper's segmenters do), and says each image's class."""

    def __init__(self, name: str = "weighted_ce", weights=None) -> None:
        super().__init__()
        self.parts = SegmentationLoss(name, weights)

    def forward(self, logits: tuple[torch.Tensor, torch.Tensor], target: torch.Tensor):
        is_hand = (target != IGNORE).flatten(1).any(1).long()
        hand_loss = nn.functional.cross_entropy(logits[0], is_hand)
        if not is_hand.any():
            return hand_loss + 0.0 * logits[1].sum()
        return hand_loss + self.parts(logits[1][is_hand == 1], target[is_hand == 1])


def class_weights(y: torch.Tensor, num_classes: int) -> np.ndarray:
    """Median-frequency class weights (C,) of targets (S,) or (S, h, w) (Eigen & Fergus)."""
    if y.ndim >= 2:
        return median_frequency_weights(*class_pixel_counts(y.numpy(), num_classes))
    counts = np.bincount(y.numpy(), minlength=num_classes)
    return median_frequency_weights(counts, np.full(num_classes, counts.sum()))
