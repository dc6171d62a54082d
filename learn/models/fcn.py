"""FCN-16s (Long, Shelhamer & Darrell, 2015) on a VGG16 backbone with a width multiplier."""

from __future__ import annotations

import torch
from torch import nn

from learn.models.blocks import bilinear_upsampler, init_weights, pad_to_multiple, scaled
from learn.models.vgg import VGGEncoder


class FCN16s(nn.Module):
    """FCN-16s: VGG16 → fc6/fc7 as convs → score at pool5 → 2× up + score at pool4 → 16× up.

    fc6 is a 7 × 7 conv and fc7 a 1 × 1 conv of ``round(4096 · width)`` channels each, with
    ReLU and dropout; the pool4 score layer starts at zero and the upsamplers as bilinear
    interpolation (the 16× one stays fixed, as in the reference implementation). Instead of the
    reference's 100-px input padding, the input is zero-padded at the bottom/right to a multiple
    of 32 (zero = no pressure) and the output cropped back.

    ``(B, in_channels, H, W)`` float in [0, 1] → ``(B, num_classes, H, W)`` logits (softmax
    lives in the loss / prediction). ``batch_norm`` adds BN to the backbone (not in the
    original; it makes training from scratch practical).
    """

    task = "segmentation"

    def __init__(
        self,
        num_classes: int = 7,
        in_channels: int = 1,
        width: float = 0.25,
        *,
        batch_norm: bool = True,
        dropout: float = 0.5,
    ) -> None:
        super().__init__()
        self.num_classes, self.in_channels = num_classes, in_channels
        self.encoder = VGGEncoder(in_channels, width, batch_norm=batch_norm)
        c4, c5, c_fc = *self.encoder.out_channels[-2:], scaled(4096, width)
        self.fc67 = nn.Sequential(
            nn.Conv2d(c5, c_fc, 7, padding=3),
            nn.ReLU(inplace=True),
            nn.Dropout2d(dropout),
            nn.Conv2d(c_fc, c_fc, 1),
            nn.ReLU(inplace=True),
            nn.Dropout2d(dropout),
        )
        self.score_fr = nn.Conv2d(c_fc, num_classes, 1)
        self.score_pool4 = nn.Conv2d(c4, num_classes, 1)
        init_weights(self)
        nn.init.zeros_(self.score_pool4.weight)
        nn.init.zeros_(self.score_pool4.bias)
        self.upscore2 = bilinear_upsampler(num_classes, 2)
        self.upscore16 = bilinear_upsampler(num_classes, 16, trainable=False)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, in_channels, H, W)`` → ``(B, num_classes, H, W)`` logits."""
        h, w = x.shape[-2:]
        pooled = self.encoder(pad_to_multiple(x, 32))
        score = self.upscore2(self.score_fr(self.fc67(pooled[-1])))
        score = score + self.score_pool4(pooled[-2])
        return self.upscore16(score)[..., :h, :w]
