"""Weight averaging: an exponential moving average (EMA, Polyak averaging) of a network's
weights, updated after every optimizer step, validated and kept in place of the raw weights.

    ema = make_ema(model, optimizer, decay=0.998)   # None when decay is 0 (off)
    ...train...                                     # each optimizer.step() updates ema
    scored = ema.module                             # the averaged network, same layers

Update ``t`` (counted from 0, after the first step's copy) sets ``w_bar <- d_t * w_bar +
(1 - d_t) * w`` with ``d_t = min(decay, (1 + t) / (10 + t))``: ``tf.train.ExponentialMovingAverage``
with ``num_updates``, so the average forgets the initial weights within tens of steps and
then spans roughly the last ``1 / (1 - decay)`` steps. Without the warm-up the initial weights
weigh ``decay ** t`` (0.17 after 900 steps at 0.998), and in batch-norm running variances that
is fatal: HandsNet's first layer has true variances near 1e-4 against the initial 1, so its
averaged network normalised its features ~30 times too small and predicted one class.

Batch-norm running statistics are averaged like the weights (as ``use_buffers=True`` of
``torch.optim.swa_utils.AveragedModel``, on which this is built), so the averaged network is
scored as it stands, without a pass over the data to recompute them; integer buffers (batches
seen) are copied.
"""

from __future__ import annotations

import torch
from torch import nn
from torch.optim import Optimizer
from torch.optim.swa_utils import AveragedModel


def ema_decay_at(decay: float, t: int) -> float:
    """The decay of update ``t`` (0-based count of updates after the first step's copy)."""
    return min(decay, (1.0 + t) / (10.0 + t))


def _ema_update(decay: float):
    """An ``AveragedModel`` ``multi_avg_fn``: averaged and current tensors, updates so far."""

    @torch.no_grad()
    def update(averaged: list[torch.Tensor], current: list[torch.Tensor], n_averaged) -> None:
        d = ema_decay_at(decay, int(n_averaged) - 1)
        for a, c in zip(averaged, current, strict=True):
            if a.is_floating_point():
                a.lerp_(c, 1.0 - d)
            else:
                a.copy_(c)

    return update


def make_ema(model: nn.Module, optimizer: Optimizer, decay: float) -> AveragedModel | None:
    """An EMA of ``model``'s parameters and buffers that ``optimizer.step()`` keeps up to date
    (a step post-hook), or None when ``decay`` is 0. ``decay`` in [0, 1): per optimizer step."""
    if not 0.0 <= decay < 1.0:
        raise ValueError(f"make_ema: decay must be in [0, 1), not {decay}")
    if decay == 0.0:
        return None
    ema = AveragedModel(model, multi_avg_fn=_ema_update(decay), use_buffers=True)
    optimizer.register_step_post_hook(lambda *_: ema.update_parameters(model))
    return ema
