"""Test-time flips: a network's prediction averaged over the views it was trained on.

    tta = FlipTTA(model, views=(0, 1, 2))   # original, columns reversed, rows reversed
    log_p = tta(x)                           # (B, C) or (B, C, h, w) log of the mean softmax

Each view of the input is one flip (`VIEW_DIMS`); a segmenter's output is flipped back before
the mean, so every pixel averages the class probabilities it got in each view. The views go
through the network as one batch of ``V · B`` images. The output is the log of the mean
probability, so ``argmax`` gives the averaged decision and ``softmax`` gives the mean
probability back. A network trained with flips (``learn.train.views_of``) has seen each view;
flips also mirror a hand, so the mean pools a right-hand and a left-hand reading of one print.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch
from torch import nn

#: Axes each view reverses on a (..., H, W) tensor: 0 original, 1 columns (a horizontal flip),
#: 2 rows (a vertical flip), 3 both (a 180-degree turn).
VIEW_DIMS: dict[int, tuple[int, ...]] = {0: (), 1: (-1,), 2: (-2,), 3: (-2, -1)}

#: The paper's threefold augmentation: original, columns reversed, rows reversed.
PAPER_VIEWS: tuple[int, ...] = (0, 1, 2)


def flip_view(x: torch.Tensor, view: int) -> torch.Tensor:
    """``x`` (..., H, W) in view ``view`` (`VIEW_DIMS`); a flip is its own inverse."""
    dims = VIEW_DIMS[int(view)]
    return x.flip(dims) if dims else x


def flip_array(arr: np.ndarray, view: int) -> np.ndarray:
    """numpy ``arr`` (..., H, W) in view ``view`` (`VIEW_DIMS`), as a strided view (no copy)."""
    dims = VIEW_DIMS[int(view)]
    return np.flip(arr, dims) if dims else arr


class FlipTTA(nn.Module):
    """``model`` with test-time flips over ``views`` (ids of `VIEW_DIMS`, at least two).

    forward: x (B, 1, h, w) → (B, C) or (B, C, h, w) float32, the log of the mean softmax over
    the views. Keeps the wrapped model's ``num_classes``, ``in_channels``, ``task`` and
    ``input_size`` attributes.
    """

    def __init__(self, model: nn.Module, views: Sequence[int] = (0, 1, 2)) -> None:
        super().__init__()
        views = tuple(int(v) for v in views)
        if len(views) < 2 or len(set(views)) != len(views) or set(views) - set(VIEW_DIMS):
            raise ValueError(f"views {views}: give two or more distinct ids of {set(VIEW_DIMS)}")
        self.net, self.views = model, views
        for name in ("num_classes", "in_channels", "task", "input_size", "bf16"):
            if hasattr(model, name):
                setattr(self, name, getattr(model, name))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, C_in, h, w)`` → log of the mean softmax, ``(B, C)`` or ``(B, C, h, w)``."""
        n = len(x)
        out = self.net(torch.cat([flip_view(x, v) for v in self.views])).float().softmax(1)
        probs = out.split(n)
        if out.ndim == 4:  # a segmenter: flip each view's output back onto the input's pixels
            probs = [flip_view(p, v) for p, v in zip(probs, self.views, strict=True)]
        mean = torch.stack(list(probs)).mean(0)
        return mean.clamp_min(torch.finfo(mean.dtype).tiny).log()
