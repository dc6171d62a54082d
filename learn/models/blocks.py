"""Small building blocks shared by the networks: conv + BN + ReLU, VGG stages, bilinear kernels.

Every block works on ``(B, C, H, W)`` float tensors; sizes are in pixels.
"""

from __future__ import annotations

from itertools import pairwise

import torch
from torch import nn
from torch.nn.utils.fusion import fuse_conv_bn_eval

#: The VGG16 layout: output channels of the 13 convolutions at width 1.0, one tuple per stage
#: (each stage ends with a 2 × 2 max pooling of stride 2).
VGG16_STAGES: tuple[tuple[int, ...], ...] = (
    (64, 64),
    (128, 128),
    (256, 256, 256),
    (512, 512, 512),
    (512, 512, 512),
)


def scaled(channels: int, width: float) -> int:
    """Channels after a width multiplier: ``round(channels * width)``, at least 1."""
    return max(1, round(channels * width))


class ConvBNReLU(nn.Sequential):
    """Conv (stride 1) → optional batch norm → ReLU; ``(B, in, H, W) → (B, out, H', W')``.

    ``padding=None`` keeps the size (``kernel // 2``); with batch norm the conv has no bias.
    """

    def __init__(
        self,
        in_channels: int,
        out_channels: int,
        kernel_size: int = 3,
        *,
        padding: int | None = None,
        batch_norm: bool = True,
    ) -> None:
        pad = kernel_size // 2 if padding is None else padding
        layers: list[nn.Module] = [
            nn.Conv2d(in_channels, out_channels, kernel_size, padding=pad, bias=not batch_norm)
        ]
        if batch_norm:
            layers.append(nn.BatchNorm2d(out_channels))
        layers.append(nn.ReLU(inplace=True))
        super().__init__(*layers)


def conv_stack(channels: list[int], *, batch_norm: bool) -> nn.Sequential:
    """3 × 3 same-size ``ConvBNReLU`` blocks taking ``channels[0]`` to ``channels[-1]``."""
    return nn.Sequential(
        *(ConvBNReLU(a, b, 3, batch_norm=batch_norm) for a, b in pairwise(channels))
    )


def bilinear_kernel(channels: int, kernel_size: int) -> torch.Tensor:
    """Weights ``(channels, channels, k, k)`` making a transposed conv a bilinear upsampler.

    As in Long et al.'s FCN (``upsample_filt``): channel ``c`` maps only to channel ``c``.
    """
    factor = (kernel_size + 1) // 2
    center = factor - 1 if kernel_size % 2 == 1 else factor - 0.5
    og = torch.arange(kernel_size, dtype=torch.float32)
    filt1d = 1 - (og - center).abs() / factor
    filt = filt1d[:, None] * filt1d[None, :]
    weight = torch.zeros(channels, channels, kernel_size, kernel_size)
    weight[range(channels), range(channels)] = filt
    return weight


def bilinear_upsampler(channels: int, factor: int, *, trainable: bool = True) -> nn.ConvTranspose2d:
    """Transposed conv upsampling ``(B, C, h, w) → (B, C, factor·h, factor·w)``, bilinear init."""
    up = nn.ConvTranspose2d(
        channels, channels, 2 * factor, stride=factor, padding=factor // 2, bias=False
    )
    with torch.no_grad():
        up.weight.copy_(bilinear_kernel(channels, 2 * factor))
    up.weight.requires_grad_(trainable)
    return up


def pad_to_multiple(x: torch.Tensor, multiple: int) -> torch.Tensor:
    """Zero-pad ``(B, C, H, W)`` at the bottom/right so H and W are multiples of ``multiple``.

    Zero is the tactile background (no pressure), so padding adds no fake contact.
    """
    h, w = x.shape[-2:]
    pad_h, pad_w = (-h) % multiple, (-w) % multiple
    if pad_h == 0 and pad_w == 0:
        return x
    return nn.functional.pad(x, (0, pad_w, 0, pad_h))


def init_weights(module: nn.Module) -> None:
    """He (fan-out) init for convs, unit/zero for batch norm, Glorot for linear layers.

    Transposed convs are left alone (their bilinear init is set by their constructor).
    """
    for m in module.modules():
        if isinstance(m, nn.Conv2d):
            nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
            if m.bias is not None:
                nn.init.zeros_(m.bias)
        elif isinstance(m, nn.BatchNorm2d | nn.BatchNorm1d):
            nn.init.ones_(m.weight)
            nn.init.zeros_(m.bias)
        elif isinstance(m, nn.Linear):
            nn.init.xavier_uniform_(m.weight)
            nn.init.zeros_(m.bias)


def fold_batch_norm(module: nn.Module) -> nn.Module:
    """In place: every ``Conv2d`` followed by a ``BatchNorm2d`` in a ``Sequential`` becomes one
    conv with the normalisation folded in (eval-mode maths), the BN an ``Identity``.

    Call on a model in eval mode only; training it afterwards would train without batch norm.
    """
    for seq in module.modules():
        if not isinstance(seq, nn.Sequential):
            continue
        for i in range(len(seq) - 1):
            if isinstance(seq[i], nn.Conv2d) and isinstance(seq[i + 1], nn.BatchNorm2d):
                seq[i] = fuse_conv_bn_eval(seq[i], seq[i + 1])
                seq[i + 1] = nn.Identity()
    return module
