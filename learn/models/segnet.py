"""SegNet (Badrinarayanan et al., 2017): VGG16 encoder, decoder unpooling with its indices."""

from __future__ import annotations

import torch
from torch import nn

from learn.models.blocks import VGG16_STAGES, conv_stack, init_weights
from learn.models.vgg import VGGEncoder


def _decoder_channels(enc_channels: list[int]) -> list[list[int]]:
    """Channel chains of the 5 decoder stages, deepest first, mirroring the encoder.

    Stage ``s`` keeps ``c_s`` for all but its last conv, which goes to ``c_{s-1}``; the
    shallowest stage has one conv fewer: the classifier conv is its last (13 decoder convs in
    all, as in SegNet: 512·3 → 512·2, 256 → 256·2, 128 → 128, 64 → 64, classes).
    """
    chains = []
    for s in reversed(range(len(enc_channels))):
        c_s, n_convs = enc_channels[s], len(VGG16_STAGES[s])
        chains.append([c_s] * n_convs + ([enc_channels[s - 1]] if s > 0 else []))
    return chains


class SegNet(nn.Module):
    """SegNet: encoder (VGG16's 13 convs + BN), decoder (13 convs + BN) and a 3 × 3 classifier.

    Each decoder stage unpools with the pooling indices of the matching encoder stage, to the
    encoder's pre-pooling size, so any input size works (pooling uses ``ceil_mode``).

    ``(B, in_channels, H, W)`` float in [0, 1] → ``(B, num_classes, H, W)`` logits (softmax lives
    in the loss / prediction). ``width`` scales every channel count (1.0 = 64 … 512).
    """

    task = "segmentation"

    def __init__(self, num_classes: int = 7, in_channels: int = 1, width: float = 0.5) -> None:
        super().__init__()
        self.num_classes, self.in_channels = num_classes, in_channels
        self.encoder = VGGEncoder(in_channels, width, batch_norm=True)
        self.decoder = nn.ModuleList(
            conv_stack(chain, batch_norm=True)
            for chain in _decoder_channels(self.encoder.out_channels)
        )
        self.unpool = nn.MaxUnpool2d(2, 2)
        self.classifier = nn.Conv2d(self.encoder.out_channels[0], num_classes, 3, padding=1)
        init_weights(self)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, in_channels, H, W)`` → ``(B, num_classes, H, W)`` logits."""
        pooled, indices, sizes = self.encoder.forward_with_indices(x)
        y = pooled[-1]
        for stage, idx, size in zip(self.decoder, reversed(indices), reversed(sizes), strict=True):
            y = stage(self.unpool(y, idx, output_size=size[-2:]))
        return self.classifier(y)
