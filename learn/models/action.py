"""The network that names the action of a press (grasp, twist, push, pull, free touch) from its
10 Hz sequence of tactile images.

`Action3D` takes ``(B, T, in_channels, h, w)`` float in [0, 1] — T frames, zeros after the
press — and returns ``(B, num_classes)`` logits; its ``task`` is ``"sequence"``. A small 3D CNN
over (T, h, w) (16-128 channels times ``width``), the maximum over time and space. In training
it cuts each sequence after a random number of frames (`RandomPrefix`), so that it answers from
the first frames of a press as well as from all of it. (A per-frame CNN with a temporal
convolution scored lower: docs/findings.md, "Actions: a temporal convolution over per-frame
features".)
"""

from __future__ import annotations

import torch
from torch import nn

from learn.models.blocks import init_weights, scaled
from tactile.errors import ConfigError

MIN_SIDE_PX = 8  # smallest frame side the three 2 x 2 poolings leave a pixel of, px


def check_sequence(x: torch.Tensor, in_channels: int, name: str) -> None:
    """ConfigError unless ``x`` is ``(B, T, in_channels, h, w)``, sides `MIN_SIDE_PX` or more."""
    if x.ndim != 5 or x.shape[2] != in_channels or min(x.shape[-2:]) < MIN_SIDE_PX:
        raise ConfigError(
            f"{name} takes sequences (B, T, {in_channels}, h, w) with h, w >= {MIN_SIDE_PX} px; "
            f"got {tuple(x.shape)}. Fix: give frames stacked on axis 1 (learn.data.sequences)"
        )


class RandomPrefix(nn.Module):
    """In training, each sequence ``(B, T, ...)`` keeps, with probability ``p``, only its first
    k frames (the others zeroed), k uniform over 1 .. its last frame with any pressure: what a
    robot holds k frames into a press. The identity in eval mode and for ``p = 0``."""

    def __init__(self, p: float = 0.5) -> None:
        super().__init__()
        if not 0.0 <= p <= 1.0:
            raise ConfigError(f"prefix probability {p}: give a value in [0, 1]")
        self.p = float(p)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, T, ...)`` → the same shape, some sequences cut (training only)."""
        if not self.training or self.p == 0.0:
            return x
        b, t = x.shape[:2]
        lit = x.flatten(2).amax(2) > 0
        last = t - lit.flip(1).to(torch.int64).argmax(1)  # 1 + the last lit frame (t: none)
        k = 1 + (torch.rand(b, device=x.device) * last).to(torch.int64)
        kept = torch.where(torch.rand(b, device=x.device) < self.p, k, t)
        keep = torch.arange(t, device=x.device)[None] < kept[:, None]
        return x * keep.view(b, t, *([1] * (x.ndim - 2))).to(x.dtype)


def _init_3d(module: nn.Module) -> None:
    """He (fan-out) init of the 3D convolutions (`init_weights` does the 2D and linear ones)."""
    for m in module.modules():
        if isinstance(m, nn.Conv3d):
            nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
        elif isinstance(m, nn.BatchNorm3d):
            nn.init.ones_(m.weight)
            nn.init.zeros_(m.bias)


class Action3D(nn.Module):
    """A small 3D CNN: ``(B, T, C, h, w)`` → ``(B, num_classes)``. Four conv (3D, "same"
    padding) + batch norm + ReLU blocks of ``width`` × (16, 32, 64, 128) channels, the first
    3 × 5 × 5 (frames × rows × columns), the others 3 × 3 × 3; max pooling 1 × 2 × 2, 1 × 2 × 2,
    2 × 2 × 2 between them; the maximum over what is left; dropout; a linear layer."""

    task = "sequence"

    def __init__(
        self,
        num_classes: int = 8,
        in_channels: int = 1,
        width: float = 1.0,
        prefix_p: float = 0.5,
        dropout: float = 0.3,
    ) -> None:
        super().__init__()
        self.num_classes, self.in_channels = num_classes, in_channels
        self.prefix = RandomPrefix(prefix_p)
        c = [scaled(n, width) for n in (16, 32, 64, 128)]
        self.features = nn.Sequential(
            *_conv3d(in_channels, c[0], (3, 5, 5)),
            nn.MaxPool3d((1, 2, 2)),
            *_conv3d(c[0], c[1], (3, 3, 3)),
            nn.MaxPool3d((1, 2, 2)),
            *_conv3d(c[1], c[2], (3, 3, 3)),
            nn.MaxPool3d((2, 2, 2), ceil_mode=True),
            *_conv3d(c[2], c[3], (3, 3, 3)),
            nn.AdaptiveMaxPool3d(1),
        )
        self.head = nn.Sequential(nn.Flatten(), nn.Dropout(dropout), nn.Linear(c[3], num_classes))
        init_weights(self)
        _init_3d(self)
        nn.init.zeros_(self.head[-1].weight)  # every press starts at even odds

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, T, C, h, w)`` → ``(B, num_classes)`` logits."""
        check_sequence(x, self.in_channels, "Action3D")
        return self.head(self.features(self.prefix(x).transpose(1, 2)))


def _conv3d(c_in: int, c_out: int, kernel: tuple[int, int, int]) -> list[nn.Module]:
    pad = tuple(k // 2 for k in kernel)
    return [
        nn.Conv3d(c_in, c_out, kernel, padding=pad, bias=False),
        nn.BatchNorm3d(c_out),
        nn.ReLU(inplace=True),
    ]
