"""Batch augmentations beyond the paper's flips: random shifts (`RunConfig.shift_px`) and mixup
(`RunConfig.mixup_alpha`).

    x, y = random_shift(x, y, 8)     # each item moved by up to 8 px along each axis, zero-filled
    x, q = mixup(x, y, 0.2, 2)       # classifier batch mixed with a shuffled copy of itself

Shifts: a print means much the same wherever it lands on the map, and ~1,000 training hands
show each network few positions. Measured on the paper-sized forearm set at 8 px, it does not
hold: HandsNet lost 2.85 points at seeds 0 and 1, SegNet 1.06 mIoU points (docs/learning.md, "Random
shifts"), so `RunConfig.shift_px` is 0 by default.

Mixup (Zhang et al., ICLR 2018) trains a classifier on convex mixtures of two images and of
their one-hot targets, a regulariser aimed at what keeps HandsNet at ~92 %: it fits its training
people's prints and not new people's (docs/learning.md, "Where the models fail").

Both draw from torch's global generator, which `learn.train.train_epoch` seeds per epoch, so a
run (and a resumed one) gets the same shifts and mixtures on every machine.
"""

from __future__ import annotations

import torch


def random_shift(
    x: torch.Tensor, y: torch.Tensor, max_px: int, generator: torch.Generator | None = None
) -> tuple[torch.Tensor, torch.Tensor]:
    """Move each item of ``x`` (B, C, H, W) by integer pixels (dy, dx), each uniform over
    ``-max_px .. max_px``; pixels shifted in from outside are 0 (no pressure). ``y``: class
    targets (B,) are returned as they are, label images (B, H, W) move with their images (0 =
    background shifted in). ``max_px`` 0 returns the inputs unchanged."""
    if max_px < 0:
        raise ValueError(f"random_shift: max_px={max_px} must be >= 0")
    if max_px == 0:
        return x, y
    b, _, h, w = x.shape
    d = torch.randint(-max_px, max_px + 1, (b, 2), generator=generator)
    rows = torch.arange(h)[None, :] - d[:, :1]  # (B, H): output row r reads input row r - dy
    cols = torch.arange(w)[None, :] - d[:, 1:]  # (B, W)
    inside = ((rows >= 0) & (rows < h))[:, :, None] & ((cols >= 0) & (cols < w))[:, None, :]
    items = torch.arange(b)[:, None, None]
    r, c = rows.clamp(0, h - 1)[:, :, None], cols.clamp(0, w - 1)[:, None, :]
    moved = x.permute(0, 2, 3, 1)[items, r, c].permute(0, 3, 1, 2)  # (B, C, H, W)
    moved = moved * inside[:, None].to(x.dtype)
    if y.ndim == 3:
        y = y[items, r, c] * inside.to(y.dtype)
    return moved.contiguous(), y


def mix_batch(
    x: torch.Tensor, y: torch.Tensor, lam: float, perm: torch.Tensor, num_classes: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """Images ``lam·x + (1 − lam)·x[perm]`` (B, C, H, W) and targets ``lam·onehot(y) + (1 −
    lam)·onehot(y[perm])`` (B, num_classes) float, probabilities summing to 1 per item.
    ``y``: (B,) int64 class ids; ``perm``: (B,) a permutation of the batch."""
    if y.ndim != 1:
        raise ValueError(f"mixup mixes class targets (B,), not label images {tuple(y.shape)}")
    onehot = torch.nn.functional.one_hot(y, num_classes).to(x.dtype)
    return lam * x + (1 - lam) * x[perm], lam * onehot + (1 - lam) * onehot[perm]


def mixup(
    x: torch.Tensor, y: torch.Tensor, alpha: float, num_classes: int
) -> tuple[torch.Tensor, torch.Tensor]:
    """`mix_batch` with one ``lam ~ Beta(alpha, alpha)`` for the batch and a uniform random
    permutation, drawn from torch's global generator. ``alpha`` 0 returns the inputs unchanged
    (targets stay class ids (B,))."""
    if alpha < 0:
        raise ValueError(f"mixup: alpha={alpha} must be >= 0")
    if alpha == 0:
        return x, y
    a = torch.tensor(float(alpha))
    lam = float(torch.distributions.Beta(a, a).sample())
    return mix_batch(x, y, lam, torch.randperm(len(y)), num_classes)
