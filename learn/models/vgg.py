"""VGG16-style encoder and classifier with a width multiplier, and loading of VGG16 weights.

ImageNet weights cannot be downloaded here: :func:`load_vgg_weights` reads a user-provided
torchvision-format ``state_dict`` file (``vgg16`` or ``vgg16_bn``) and maps its 13 convolutions
by order onto ours; our own synthetic pretraining is loaded with :mod:`learn.finetune`.
"""

from __future__ import annotations

from pathlib import Path

import torch
from torch import nn

from learn.models.blocks import VGG16_STAGES, conv_stack, init_weights, scaled
from tactile.errors import ConfigError


class VGGEncoder(nn.Module):
    """The 13 convolutions of VGG16 in 5 stages, each ended by 2 × 2 max pooling (stride 2).

    Pooling uses ``ceil_mode`` so no border pixel is dropped at sizes not divisible by 32
    (68 × 100 → 34 × 50 → 17 × 25 → 9 × 13 → 5 × 7 → 3 × 4).
    """

    def __init__(
        self, in_channels: int = 1, width: float = 1.0, *, batch_norm: bool = True
    ) -> None:
        super().__init__()
        self.in_channels, self.width = in_channels, width
        widths = [[scaled(c, width) for c in stage] for stage in VGG16_STAGES]
        inputs = [in_channels] + [stage[-1] for stage in widths[:-1]]
        self.stages = nn.ModuleList(
            conv_stack([c_in, *stage], batch_norm=batch_norm)
            for c_in, stage in zip(inputs, widths, strict=True)
        )
        self.pool = nn.MaxPool2d(2, 2, ceil_mode=True, return_indices=True)
        self.out_channels: list[int] = [stage[-1] for stage in widths]

    def forward(self, x: torch.Tensor) -> list[torch.Tensor]:
        """``(B, in, H, W)`` → the 5 pooled stage outputs (pool1 … pool5), each halving H, W."""
        return self.forward_with_indices(x)[0]

    def forward_with_indices(
        self, x: torch.Tensor
    ) -> tuple[list[torch.Tensor], list[torch.Tensor], list[torch.Size]]:
        """Pooled outputs, pooling indices and pre-pooling sizes of each stage (for SegNet)."""
        pooled, indices, sizes = [], [], []
        for stage in self.stages:
            x = stage(x)
            sizes.append(x.shape)
            x, idx = self.pool(x)
            pooled.append(x)
            indices.append(idx)
        return pooled, indices, sizes


class VGGClassifier(nn.Module):
    """VGG16-style classifier: encoder → global average pool → fc6 → fc7 → fc8 (logits).

    ``(B, in_channels, H, W)`` float in [0, 1] → ``(B, num_classes)`` logits (softmax lives in
    the loss / prediction). fc6 and fc7 have ``round(4096 · width)`` units; global average
    pooling makes any input size ≥ 1 px work. ``features(x)`` gives fc7 (or pool5) vectors for
    the features + linear SVM variant (:mod:`learn.vgg_svm`).
    """

    task = "classification"

    def __init__(
        self,
        num_classes: int = 2,
        in_channels: int = 1,
        width: float = 0.25,
        *,
        batch_norm: bool = True,
        dropout: float = 0.5,
    ) -> None:
        super().__init__()
        self.num_classes, self.in_channels = num_classes, in_channels
        self.encoder = VGGEncoder(in_channels, width, batch_norm=batch_norm)
        hidden = scaled(4096, width)
        self.fc67 = nn.Sequential(
            nn.Flatten(),
            nn.Linear(self.encoder.out_channels[-1], hidden),
            nn.ReLU(inplace=True),
            nn.Dropout(dropout),
            nn.Linear(hidden, hidden),
            nn.ReLU(inplace=True),
            nn.Dropout(dropout),
        )
        self.fc8 = nn.Linear(hidden, num_classes)
        init_weights(self)

    def features(self, x: torch.Tensor, layer: str = "fc7") -> torch.Tensor:
        """``(B, in, H, W)`` → ``(B, D)``: ``"fc7"`` (after ReLU) or ``"pool5"`` (avg-pooled)."""
        pool5 = self.encoder(x)[-1].mean(dim=(-2, -1))
        if layer == "pool5":
            return pool5
        if layer == "fc7":
            return self.fc67(pool5)
        raise ConfigError(f"unknown VGG feature layer {layer!r}; choose 'fc7' or 'pool5'")

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, in, H, W)`` → ``(B, num_classes)`` logits."""
        return self.fc8(self.features(x, "fc7"))


def _affine_of(entry: dict[str, torch.Tensor]) -> tuple[torch.Tensor, torch.Tensor]:
    """Per-channel ``(scale, shift)`` so that a file's conv(+BN) output = scale·(w∗x) + shift."""
    bias = entry.get("bias", torch.zeros(entry["weight"].shape[0]))
    if "bn.running_mean" not in entry:
        return torch.ones_like(bias), bias
    scale = entry["bn.weight"] / torch.sqrt(entry["bn.running_var"] + 1e-5)
    return scale, (bias - entry["bn.running_mean"]) * scale + entry["bn.bias"]


def _read_vgg_convs(state: dict[str, torch.Tensor]) -> list[dict[str, torch.Tensor]]:
    """Group a torchvision ``features.{i}.*`` state dict into conv entries (with their BN)."""
    modules: dict[int, dict[str, torch.Tensor]] = {}
    for key, value in state.items():
        parts = key.split(".")
        if len(parts) == 3 and parts[0] == "features" and parts[1].isdigit():
            modules.setdefault(int(parts[1]), {})[parts[2]] = value
    convs: list[dict[str, torch.Tensor]] = []
    for i in sorted(modules):
        module = modules[i]
        if module.get("weight") is not None and module["weight"].ndim == 4:
            convs.append(dict(module))
        elif "running_mean" in module and convs:
            convs[-1].update({f"bn.{k}": v for k, v in module.items()})
    return convs


def _conv_weight(weight: torch.Tensor, target: torch.Tensor, index: int) -> torch.Tensor:
    """The file's conv weight shaped as ``target``; RGB filters averaged for 1-channel input."""
    if index == 0 and weight.shape[1] == 3 and target.shape[1] == 1:
        weight = weight.mean(dim=1, keepdim=True)
    if weight.shape != target.shape:
        raise ConfigError(
            f"VGG weights: conv {index} has shape {tuple(weight.shape)} in the file but "
            f"{tuple(target.shape)} in the model; load VGG16 weights into width=1.0"
        )
    return weight


@torch.no_grad()
def _load_conv(conv: nn.Conv2d, bn: nn.BatchNorm2d | None, entry: dict, index: int) -> None:
    """Copy one file conv (+ its BN) into ``conv`` (+ ``bn``), exactly in eval mode."""
    weight = _conv_weight(entry["weight"], conv.weight, index)
    scale, shift = _affine_of(entry)
    if bn is None:
        conv.weight.copy_(weight * scale[:, None, None, None])
        conv.bias.copy_(shift)
    elif "bn.running_mean" in entry:
        conv.weight.copy_(weight)
        bias = entry.get("bias", torch.zeros_like(shift))
        bn.running_mean.copy_(entry["bn.running_mean"] - bias)
        bn.running_var.copy_(entry["bn.running_var"])
        bn.weight.copy_(entry["bn.weight"])
        bn.bias.copy_(entry["bn.bias"])
    else:
        conv.weight.copy_(weight)
        bn.reset_running_stats()  # mean 0, var 1: eval-mode BN is then weight / sqrt(1 + eps)
        bn.weight.fill_((1.0 + bn.eps) ** 0.5)
        bn.bias.copy_(shift)


def load_vgg_weights(encoder: VGGEncoder, source: str | Path | dict[str, torch.Tensor]) -> int:
    """Load a torchvision VGG16 / VGG16-BN ``state_dict`` (file or dict) into ``encoder``.

    The 13 convolutions are mapped by order (classifier weights are ignored). With
    ``in_channels=1`` the first conv's RGB filters are averaged. Biases and batch norms are
    folded so each layer computes what it computed in the file (in eval mode). Inputs are not
    ImageNet-normalized here: tactile images stay in [0, 1]. Returns the number of convs loaded.
    """
    state = torch.load(source, map_location="cpu") if isinstance(source, str | Path) else source
    entries = _read_vgg_convs(state)
    convs = [m for m in encoder.modules() if isinstance(m, nn.Conv2d)]
    if len(entries) != len(convs):
        raise ConfigError(
            f"VGG weights: found {len(entries)} convolutions under 'features.*', the model has "
            f"{len(convs)}; pass a torchvision vgg16 or vgg16_bn state_dict"
        )
    for index, (stage_block, entry) in enumerate(zip(_conv_blocks(encoder), entries, strict=True)):
        _load_conv(*stage_block, entry, index)
    return len(entries)


def _conv_blocks(encoder: VGGEncoder) -> list[tuple[nn.Conv2d, nn.BatchNorm2d | None]]:
    """(conv, batch norm or None) of each ``ConvBNReLU`` block in order."""
    blocks = []
    for stage in encoder.stages:
        for block in stage:
            bn = next((m for m in block if isinstance(m, nn.BatchNorm2d)), None)
            blocks.append((block[0], bn))
    return blocks
