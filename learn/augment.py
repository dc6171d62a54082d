"""Random translation of training batches, beyond the paper's flips (`RunConfig.shift_px`).

    x, y = random_shift(x, y, 8)     # each item moved by up to 8 px along each axis, zero-filled

The idea: a print means much the same wherever it lands on the map, and ~1,000 training hands
show each network few positions. Measured on the paper-sized forearm set at 8 px, it does not
hold: HandsNet lost 2.85 points at seeds 0 and 1, SegNet 1.06 mIoU points (docs/learning.md, "Random
shifts"), so `RunConfig.shift_px` is 0 by default. Shifts come from torch's global generator,
which `learn.train.train_epoch` seeds per epoch, so a run (and a resumed one) gets the same
shifts on every machine.
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
