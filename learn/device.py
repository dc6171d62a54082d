"""Where a run trains (`RunConfig.device`): the device check made before any work, and the
device a module's tensors live on."""

from __future__ import annotations

import itertools
from typing import TYPE_CHECKING

import torch
from torch import nn

from tactile.errors import ConfigError

if TYPE_CHECKING:
    from learn.run_config import RunConfig


def device_of(module: nn.Module) -> torch.device:
    """The device of ``module``'s first parameter or buffer (the CPU when it has none)."""
    first = next(itertools.chain(module.parameters(), module.buffers()), None)
    return torch.device("cpu") if first is None else first.device


def check_device(run: RunConfig) -> None:
    """Raise ConfigError when ``run.device`` names a GPU this torch cannot reach."""
    if run.device == "cpu":
        return
    if not torch.cuda.is_available():
        raise ConfigError(
            f"device {run.device!r}: this torch ({torch.__version__}) sees no CUDA GPU. Fix: "
            "--device cpu, or install a CUDA build of torch on a machine with an NVIDIA GPU"
        )
    index = torch.device(run.device).index or 0
    if index >= torch.cuda.device_count():
        n = torch.cuda.device_count()
        raise ConfigError(f"device {run.device!r}: this machine has {n} GPU(s). Fix: give cuda:0 "
                          f"to cuda:{n - 1}")  # fmt: skip
