"""An auxiliary head that teaches a hand / non-hand classifier what touched, not only whether a
hand did (``RunConfig.aux_types_weight``).

The generator records every contactor's type (``object: rake``, ``body: elbow``, ...; the
dataset's ``contactor`` JSON). During training a linear head on the classifier's last hidden
layer (the input of its output layer: HandsNet's 32 units) predicts that type, hands being one
type, and its cross-entropy, times the weight, is added to the loss. The head is used in
training only: checkpoints hold the plain classifier (for HandsNet exactly the paper's Table 1
network), so evaluation, prediction, int8 and compiled inference see no difference.

    head = TypeHead(model, num_types=len(names), weight=1.0)
    with head.capture(model):
        logits = model(x)                      # (B, 2)
    loss = ce(logits, y) + head.loss(head(), types)   # types (B,) int64 ids into names
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import torch
from torch import nn

from learn.breakdown import contactor_types
from tactile.errors import ConfigError

#: The type shared by every hand sample (left and right alike: a flip mirrors one into the other).
HAND_TYPE = "hand"


def type_targets(
    data_path: str | Path, indices: np.ndarray, is_hand: np.ndarray
) -> tuple[np.ndarray, tuple[str, ...]]:
    """Type ids (S,) int64 and type names of samples ``indices`` (S,) of a handskin dataset.

    is_hand : (S,) bool, the samples' class. Hands get id 0 (`HAND_TYPE`); a non-hand sample
    gets its ``"<kind>: <type>"`` (`learn.breakdown.contactor_types`), ids in sorted name order
    after the hand. ConfigError when no non-hand sample has a recorded type (e.g. ingested
    recordings), since the head would then learn nothing beyond the class.
    """
    is_hand = np.asarray(is_hand, bool)
    types = np.array(contactor_types(data_path, indices), dtype=object)
    types[is_hand] = HAND_TYPE
    others = sorted(set(types[~is_hand]) - {"unknown"})
    if not others:
        raise ConfigError(
            f"{data_path}: its non-hand samples record no contactor type (the dataset's "
            "'contactor' field), so aux_types_weight has nothing to teach. Fix: "
            "aux_types_weight = 0, or train on a dataset made by handskin generate"
        )
    names = (HAND_TYPE, *others, *(("unknown",) if "unknown" in set(types) else ()))
    ids = np.array([names.index(t) for t in types], dtype=np.int64)
    return ids, names


def last_linear(model: nn.Module) -> nn.Linear:
    """The classifier's output layer: its last ``nn.Linear`` module."""
    linears = [m for m in model.modules() if isinstance(m, nn.Linear)]
    if not linears:
        raise ConfigError(
            f"{type(model).__name__} has no linear output layer for the type head. "
            "Fix: aux_types_weight = 0"
        )
    return linears[-1]


class TypeHead(nn.Module):
    """Linear head ``(B, F) → (B, num_types)`` on the input of ``model``'s output layer."""

    def __init__(self, model: nn.Module, num_types: int, weight: float) -> None:
        super().__init__()
        self.linear = nn.Linear(last_linear(model).in_features, num_types)
        self.weight = float(weight)
        self._hidden: torch.Tensor | None = None

    @contextmanager
    def capture(self, model: nn.Module) -> Iterator[None]:
        """Keep the hidden features ``(B, F)`` of ``model``'s forward passes inside the block."""

        def grab(_module: nn.Module, inputs: tuple[torch.Tensor, ...], _out: torch.Tensor) -> None:
            self._hidden = inputs[0]

        handle = last_linear(model).register_forward_hook(grab)
        try:
            yield
        finally:
            handle.remove()

    def forward(self) -> torch.Tensor:
        """Type logits ``(B, num_types)`` of the last captured forward pass."""
        if self._hidden is None:
            raise RuntimeError("TypeHead: no forward pass captured; run the model in capture()")
        return self.linear(self._hidden)

    def loss(self, logits: torch.Tensor, types: torch.Tensor) -> torch.Tensor:
        """``weight · CE(logits, types)``; logits from :meth:`forward`, types (B,) int64."""
        return self.weight * nn.functional.cross_entropy(logits.float(), types)
