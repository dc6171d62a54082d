"""Compact networks for the robot's control loop (*ours*): a depthwise-separable encoder-decoder
that segments the hand's parts, and the same with a hand / non-hand head on its encoder, so
that one pass answers both.

The encoder halves the image three times (a 3 × 3 stem, then depthwise-separable blocks:
MobileNet's 3 × 3 depthwise then 1 × 1 pointwise convolution, each with batch norm and ReLU);
the decoder goes back up by bilinear upsampling, joining the encoder's feature map of the same
size (U-Net's skips) through one depthwise-separable block each, and a 1 × 1 convolution gives
the classes at the input size. The classification head pools the encoder's last map (mean and
max over space) into a linear layer.

    seg = CompactSeg(num_classes=7, width=1.0)          # (B, 1, H, W) -> (B, 7, H, W)
    both = HandParts(width=1.0)                         # -> ((B, 2), (B, 7, H, W))
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import nn

from learn.models.blocks import init_weights, scaled

#: Output channels of the stem and of the encoder's stages at width 1.0 (halving the size at
#: the first block of each stage).
STEM, STAGES = 16, ((32, 32), (64, 64, 64))


class DSConv(nn.Sequential):
    """Depthwise 3 × 3 (``stride``) → BN → ReLU → pointwise 1 × 1 → BN → ReLU."""

    def __init__(self, in_channels: int, out_channels: int, stride: int = 1) -> None:
        super().__init__(
            nn.Conv2d(in_channels, in_channels, 3, stride, 1, groups=in_channels, bias=False),
            nn.BatchNorm2d(in_channels),
            nn.ReLU(inplace=True),
            nn.Conv2d(in_channels, out_channels, 1, bias=False),
            nn.BatchNorm2d(out_channels),
            nn.ReLU(inplace=True),
        )


class Encoder(nn.Module):
    """``(B, C, H, W)`` -> the feature maps at 1/2, 1/4 and 1/8 of the input size."""

    def __init__(self, in_channels: int, width: float) -> None:
        super().__init__()
        stem = scaled(STEM, width)
        self.stem = nn.Sequential(
            nn.Conv2d(in_channels, stem, 3, 2, 1, bias=False),
            nn.BatchNorm2d(stem),
            nn.ReLU(inplace=True),
        )
        self.stages = nn.ModuleList()
        c_in = stem
        for channels in STAGES:
            blocks = []
            for k, c in enumerate(channels):
                blocks.append(DSConv(c_in, scaled(c, width), stride=2 if k == 0 else 1))
                c_in = scaled(c, width)
            self.stages.append(nn.Sequential(*blocks))
        self.channels = (stem, *(scaled(c[-1], width) for c in STAGES))

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        maps = [self.stem(x)]
        for stage in self.stages:
            maps.append(stage(maps[-1]))
        return maps


class Decoder(nn.Module):
    """The encoder's maps -> ``num_classes`` logits at ``size`` (the input's)."""

    def __init__(self, channels: tuple[int, ...], num_classes: int) -> None:
        super().__init__()
        deep, *skips = channels[::-1]
        self.ups = nn.ModuleList()
        for skip in skips:
            self.ups.append(DSConv(deep + skip, skip))
            deep = skip
        self.head = nn.Conv2d(deep, num_classes, 1)

    def forward(self, maps: list[torch.Tensor], size: tuple[int, int]) -> torch.Tensor:
        x = maps[-1]
        for up, skip in zip(self.ups, maps[-2::-1], strict=True):
            x = F.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = up(torch.cat([x, skip], dim=1))
        return F.interpolate(self.head(x), size=size, mode="bilinear", align_corners=False)


class CompactSeg(nn.Module):
    """The compact segmenter: ``(B, in_channels, H, W)`` -> ``(B, num_classes, H, W)`` logits.
    ``width`` multiplies every channel count (`STEM`, `STAGES`)."""

    task = "segmentation"

    def __init__(self, num_classes: int = 7, in_channels: int = 1, width: float = 1.0) -> None:
        super().__init__()
        self.num_classes, self.in_channels = num_classes, in_channels
        self.encoder = Encoder(in_channels, width)
        self.decoder = Decoder(self.encoder.channels, num_classes)
        init_weights(self)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.decoder(self.encoder(x), x.shape[-2:])


class HandParts(CompactSeg):
    """`CompactSeg` with a hand / non-hand head on the encoder's last map (mean and max pooled,
    then linear): ``(B, in_channels, H, W)`` -> (class logits (B, 2), part logits (B,
    num_classes, H, W)) in one pass."""

    task = "both"

    def __init__(self, num_classes: int = 7, in_channels: int = 1, width: float = 1.0) -> None:
        super().__init__(num_classes, in_channels, width)
        self.classifier = nn.Linear(2 * self.encoder.channels[-1], 2)
        init_weights(self.classifier)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        maps = self.encoder(x)
        deep = maps[-1]
        pooled = torch.cat([deep.mean(dim=(2, 3)), deep.amax(dim=(2, 3))], dim=1)
        return self.classifier(pooled), self.decoder(maps, x.shape[-2:])
