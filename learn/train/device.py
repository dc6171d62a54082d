"""Where and how a run computes: the device check made before any work (``RunConfig.device``,
``RunConfig.precision``), the device a module's tensors live on, and whether this CPU has
native bfloat16."""

from __future__ import annotations

import itertools
import platform
import re

import torch
from torch import nn

from learn.config import DEVICE_PATTERN
from tactile.errors import ConfigError

_X86 = ("x86_64", "amd64", "i386", "i686")


def bf16_supported() -> bool:
    """True when this CPU has native bfloat16 for oneDNN: on x86, AVX512-BF16 or AMX (with AVX-512
    alone oneDNN emulates it, 3x slower than fp32 for HandsNet); elsewhere, as oneDNN says."""
    try:
        if not torch.ops.mkldnn._is_mkldnn_bf16_supported():
            return False
        if platform.machine().lower() in _X86:
            return bool(torch.cpu._is_avx512_bf16_supported() or torch.cpu._is_amx_tile_supported())
        return True
    except (AttributeError, RuntimeError):
        return False


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


def check_precision(device: str, precision: str) -> None:
    """Raise ConfigError when a run cannot train where and as asked: ``device`` is absent
    (:func:`check_device`), or ``precision`` is "bf16" on a CPU without native bfloat16 kernels
    (autocast would emulate them and train slower than float32) or on a GPU without bfloat16."""
    check_device(device)
    if precision != "bf16":
        return
    if device != "cpu" and not torch.cuda.is_bf16_supported():
        raise ConfigError(
            f"--precision bf16: GPU {device!r} has no bfloat16. Fix: --precision fp32"
        )
    if device == "cpu" and not bf16_supported():
        raise ConfigError(
            "--precision bf16 needs a CPU with native bfloat16 (AVX512-BF16 or AMX); this one "
            "has none, so bf16 would train slower than fp32. Fix: --precision fp32"
        )
