"""Copies of a few labelled prints, moved and turned: what a hand pressing the same way elsewhere
on the link, at another angle, would leave. Fine-tuning on a handful of real prints repeats each
one many times; moved copies keep the network from learning where on the map those few lay.

    x2, y2 = moved_copies(x, y, copies=30, shift_px=5, turn_deg=15.0, rng=rng)
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F


def moved_copies(
    x: torch.Tensor,
    y: torch.Tensor,
    copies: int,
    shift_px: int,
    turn_deg: float,
    rng: np.random.Generator,
) -> tuple[torch.Tensor, torch.Tensor]:
    """``copies`` of each print of ``x`` (N, 1, h, w) float in [0, 1] with pixel labels ``y``
    (N, h, w) int64 (unlabelled pixels, `tactile.images.labels.IGNORE`, kept), copy-major:
    (copies * N, ...). The first copy of each print is the print; every other one is turned
    about the image centre by a uniform angle in +-``turn_deg`` (deg) and moved by a uniform
    whole number of pixels in +-``shift_px`` along rows and columns (pixels taken as square).
    Images are resampled bilinearly, labels by nearest neighbour; what comes in from outside
    the image is empty skin (0, background)."""
    if copies < 1 or shift_px < 0 or turn_deg < 0:
        raise ValueError("moved_copies: copies >= 1, shift_px >= 0 and turn_deg >= 0")
    n, (h, w) = len(x), x.shape[-2:]
    xs, ys = x.repeat(copies, 1, 1, 1), y.repeat(copies, 1, 1)
    moved = n * (copies - 1)
    if moved == 0 or (shift_px == 0 and turn_deg == 0):
        return xs, ys
    angle = np.deg2rad(rng.uniform(-turn_deg, turn_deg, moved))
    shift = rng.integers(-shift_px, shift_px + 1, (moved, 2))  # rows, columns
    cos, sin = np.cos(angle), np.sin(angle)
    theta = np.zeros((moved, 2, 3))  # output -> input, in affine_grid's [-1, 1] coordinates
    theta[:, 0, 0], theta[:, 0, 1] = cos, -sin * h / w
    theta[:, 1, 0], theta[:, 1, 1] = sin * w / h, cos
    theta[:, 0, 2], theta[:, 1, 2] = -2.0 * shift[:, 1] / w, -2.0 * shift[:, 0] / h
    grid = F.affine_grid(torch.tensor(theta, dtype=x.dtype), [moved, 1, h, w], align_corners=False)
    xs[n:] = F.grid_sample(xs[n:], grid, mode="bilinear", align_corners=False)
    # labels shifted by one so that the zeros coming in from outside read as background
    lab = F.grid_sample((ys[n:, None] + 1).to(x.dtype), grid, mode="nearest", align_corners=False)
    ys[n:] = (lab[:, 0].round().long() - 1).clamp_(min=0)
    return xs, ys
