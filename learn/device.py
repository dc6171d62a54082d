"""Where a run trains (`RunConfig.device`): the device check made before any work, and the
device a module's tensors live on."""

from __future__ import annotations

import itertools
import re

import torch
from torch import nn

from learn.run_config import DEVICE_PATTERN
from tactile.errors import ConfigError


def device_of(module: nn.Module) -> torch.device:
    """The device of ``module``'s first parameter or buffer (the CPU when it has none)."""
    first = next(itertools.chain(module.parameters(), module.buffers()), None)
    return torch.device("cpu") if first is None else first.device


def check_device(device: str) -> None:
    """Raise ConfigError when ``device`` (``RunConfig.device``, ``--device``) is no training
    device's name, or names a GPU this torch cannot reach."""
    if not re.fullmatch(DEVICE_PATTERN, device):
        raise ConfigError(
            f"device {device!r} is not a training device. Fix: cpu (the default), "
            "cuda or cuda:N (a GPU)"
        )
    if device == "cpu":
        return
    if not torch.cuda.is_available():
        raise ConfigError(
            f"device {device!r}: this torch ({torch.__version__}) sees no CUDA GPU. Fix: "
            "--device cpu, or install a CUDA build of torch on a machine with an NVIDIA GPU"
        )
    index = torch.device(device).index or 0
    if index >= torch.cuda.device_count():
        n = torch.cuda.device_count()
        raise ConfigError(
            f"device {device!r}: this machine has {n} GPU(s). Fix: give cuda:0 to cuda:{n - 1}"
        )
