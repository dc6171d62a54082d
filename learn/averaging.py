"""Weight averaging: an exponential moving average (EMA, Polyak averaging) of a network's
weights, updated after every optimizer step, validated and kept in place of the raw weights.

    ema = make_ema(model, optimizer, decay=0.998)   # None when decay is 0 (off)
    ...train...                                     # each optimizer.step() updates ema
    scored = ema.module                             # the averaged network, same layers

After step ``t`` the average holds ``w_bar <- decay * w_bar + (1 - decay) * w_t`` (the first step
copies ``w_1``), an average over roughly the last ``1 / (1 - decay)`` steps. Batch-norm running
statistics are averaged the same way (``use_buffers=True``), so the averaged network is scored
as it stands, without a pass over the data to recompute them. Built on
``torch.optim.swa_utils.AveragedModel`` and ``get_ema_multi_avg_fn``.
"""

from __future__ import annotations

from torch import nn
from torch.optim import Optimizer
from torch.optim.swa_utils import AveragedModel, get_ema_multi_avg_fn


def make_ema(model: nn.Module, optimizer: Optimizer, decay: float) -> AveragedModel | None:
    """An EMA of ``model``'s parameters and buffers that ``optimizer.step()`` keeps up to date
    (a step post-hook), or None when ``decay`` is 0. ``decay`` in [0, 1): per optimizer step."""
    if not 0.0 <= decay < 1.0:
        raise ValueError(f"make_ema: decay must be in [0, 1), not {decay}")
    if decay == 0.0:
        return None
    ema = AveragedModel(model, multi_avg_fn=get_ema_multi_avg_fn(decay), use_buffers=True)
    optimizer.register_step_post_hook(lambda *_: ema.update_parameters(model))
    return ema
