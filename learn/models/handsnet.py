"""HandsNet, the hand / non-hand classifier of Albini & Cannata (IJRR 2020), Table 1."""

from __future__ import annotations

import torch
from torch import nn

from learn.models.blocks import ConvBNReLU, init_weights
from learn.numerics import flushing
from tactile.errors import ConfigError

#: (output channels, kernel size, dropout after the block's pooling) of the 4 conv blocks.
HANDSNET_BLOCKS: tuple[tuple[int, int, float], ...] = (
    (32, 7, 0.10),
    (64, 5, 0.20),
    (128, 3, 0.0),
    (256, 3, 0.0),
)


class HandsNet(nn.Module):
    """HandsNet as in Table 1 of the paper.

    Four blocks conv (padding 1, stride 1) + batch norm + ReLU, each followed by 2 × 2 max
    pooling of stride 2 (floor, as MATLAB's); dropout 10 % and 20 % after the first two blocks;
    fully connected 64 → dropout 60 % → 32 → dropout 50 % → ``num_classes``. ReLU after the
    first two fully connected layers (assumed: without it they would collapse into one linear
    map). Softmax is not part of the module: it lives in the loss / prediction.

    ``(B, in_channels, H, W)`` float in [0, 1], ``(H, W) = input_size`` → ``(B, num_classes)``
    logits. The first fully connected layer's size depends on ``input_size`` (pixels).
    ``zero_init_output`` starts the last layer's weights at zero instead of Glorot (*ours*: it
    keeps Adam from killing the narrow ReLU head in its first steps).
    """

    task = "classification"

    def __init__(
        self,
        num_classes: int = 2,
        in_channels: int = 1,
        input_size: tuple[int, int] = (68, 100),
        zero_init_output: bool = False,
    ) -> None:
        super().__init__()
        self.num_classes, self.in_channels = num_classes, in_channels
        self.input_size = (int(input_size[0]), int(input_size[1]))
        layers: list[nn.Module] = []
        c_in = in_channels
        for c_out, kernel, p_drop in HANDSNET_BLOCKS:
            layers += [ConvBNReLU(c_in, c_out, kernel, padding=1), nn.MaxPool2d(2, 2)]
            layers += [nn.Dropout(p_drop)] if p_drop > 0 else []
            c_in = c_out
        self.features = nn.Sequential(*layers)
        self.classifier = nn.Sequential(
            nn.Flatten(),
            nn.Linear(self._flat_size(), 64),
            nn.ReLU(inplace=True),
            nn.Dropout(0.6),
            nn.Linear(64, 32),
            nn.ReLU(inplace=True),
            nn.Dropout(0.5),
            nn.Linear(32, num_classes),
        )
        init_weights(self)
        if zero_init_output:
            nn.init.zeros_(self.classifier[-1].weight)

    @flushing()  # every pass of a learn/ network flushes subnormals (learn.numerics)
    def _flat_size(self) -> int:
        """Length of the flattened feature map for ``input_size`` (found by a dry run)."""
        try:
            with torch.no_grad():
                out = self.features.eval()(torch.zeros(1, self.in_channels, *self.input_size))
        except RuntimeError as err:
            raise ConfigError(
                f"HandsNet input_size {self.input_size} is too small for 4 conv + pool blocks; "
                "each side must be at least 24 pixels"
            ) from err
        self.features.train()
        return out.numel()

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, in_channels, H, W)`` → ``(B, num_classes)`` logits."""
        if tuple(x.shape[-2:]) != self.input_size:
            raise ConfigError(
                f"HandsNet built for input_size {self.input_size} got images of size "
                f"{tuple(x.shape[-2:])}; resize the images or rebuild with input_size="
            )
        return self.classifier(self.features(x))
