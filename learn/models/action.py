"""Networks that name the action of a press (grasp, twist, push, pull, free touch) from its
10 Hz sequence of tactile images.

Both take ``(B, T, in_channels, h, w)`` float in [0, 1] — T frames, zeros after the press —
and return ``(B, num_classes)`` logits; their ``task`` is ``"sequence"``.

- `ActionTCN`: each frame and its change since the frame before (so ``2 in_channels``
  channels) through HandsNet's four conv blocks (Table 1's kernels and pooling, ``width`` times
  its 32-256 channels), pooled to a 2 × 2 grid; then two causal temporal convolutions over the
  frames' features (dilations 1 and 2) and the maximum over time. A frame that is blank and
  unchanged (after the press) has zero features: the trunk does not run on it.
- `Action3D`: a small 3D CNN over (T, h, w) (16-128 channels times ``width``), the maximum
  over time and space.

In training both cut each sequence after a random number of frames (`RandomPrefix`), so that
they answer from the first frames of a press as well as from all of it.
"""

from __future__ import annotations

import torch
from torch import nn

from learn.models.blocks import ConvBNReLU, init_weights, scaled
from learn.models.handsnet import HANDSNET_BLOCKS
from tactile.errors import ConfigError

MIN_SIDE_PX = 24  # smallest frame side HandsNet's four conv + pool blocks take, px
GRID = (2, 2)  # cells each frame's features are pooled to (rows, columns)


def check_sequence(x: torch.Tensor, in_channels: int, name: str) -> None:
    """ConfigError unless ``x`` is ``(B, T, in_channels, h, w)`` with sides of 24 px or more."""
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


class SpatialSoftArgmax(nn.Module):
    """Where each feature map's response is, to a fraction of a pixel: ``(N, C, h, w)`` →
    ``(N, 2 C)``, per channel the expected row and column (-1 to 1) under the softmax of its
    responses over the pixels, at a learned temperature (Levine et al., JMLR 2016)."""

    def __init__(self) -> None:
        super().__init__()
        self.log_temperature = nn.Parameter(torch.zeros(()))

    def forward(self, f: torch.Tensor) -> torch.Tensor:
        n, c, h, w = f.shape
        p = (f.flatten(2) / self.log_temperature.exp()).softmax(-1).view(n, c, h, w)
        rows = torch.linspace(-1, 1, h, dtype=f.dtype, device=f.device)
        cols = torch.linspace(-1, 1, w, dtype=f.dtype, device=f.device)
        return torch.cat([(p.sum(3) * rows).sum(2), (p.sum(2) * cols).sum(2)], 1)


class FrameFeatures(nn.Module):
    """Per-frame features: HandsNet's conv blocks (conv, batch norm, ReLU, 2 × 2 max pooling;
    kernels 7, 5, 3, 3, padding 1) at ``width`` times its channels; the last block's maps
    averaged over each `GRID` cell (what the print looks like) and, with ``keypoints``, the
    third block's maps through `SpatialSoftArgmax` (where its parts are):
    ``(N, in_channels, h, w)`` → ``(N, size)``."""

    def __init__(self, in_channels: int, width: float, keypoints: bool = True) -> None:
        super().__init__()
        blocks: list[nn.Module] = []
        c_in = in_channels
        for c_out, kernel, _ in HANDSNET_BLOCKS:
            c_out = scaled(c_out, width)
            blocks += [ConvBNReLU(c_in, c_out, kernel, padding=1), nn.MaxPool2d(2, 2)]
            c_in = c_out
        self.early, self.late = nn.Sequential(*blocks[:5]), nn.Sequential(*blocks[5:])
        self.pool = nn.AdaptiveAvgPool2d(GRID)
        self.keypoints = SpatialSoftArgmax() if keypoints else None
        third = scaled(HANDSNET_BLOCKS[2][0], width)
        self.size = c_in * GRID[0] * GRID[1] + (2 * third if keypoints else 0)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        early = self.early(x)
        looks = self.pool(self.late(early)).flatten(1)
        return looks if self.keypoints is None else torch.cat([looks, self.keypoints(early)], 1)


class CausalConv1d(nn.Conv1d):
    """A temporal convolution ``(B, C, T) → (B, C', T)`` whose output at frame t sees frames
    t - dilation (kernel - 1) .. t only (zero padding before the first frame)."""

    def __init__(self, c_in: int, c_out: int, kernel: int, dilation: int = 1) -> None:
        super().__init__(c_in, c_out, kernel, dilation=dilation, bias=False)
        self.left = dilation * (kernel - 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return super().forward(nn.functional.pad(x, (self.left, 0)))


def _init_temporal(module: nn.Module) -> None:
    """He (fan-out) init of the 1D and 3D convolutions (`init_weights` does the 2D ones)."""
    for m in module.modules():
        if isinstance(m, nn.Conv1d | nn.Conv3d):
            nn.init.kaiming_normal_(m.weight, mode="fan_out", nonlinearity="relu")
        elif isinstance(m, nn.BatchNorm3d):
            nn.init.ones_(m.weight)
            nn.init.zeros_(m.bias)


class ActionTCN(nn.Module):
    """Per-frame features of the tactile images (HandsNet's trunk on each frame and its change),
    then a causal temporal convolution network: ``(B, T, C, h, w)`` → ``(B, num_classes)``.

    ``width`` scales HandsNet's channels; ``hidden``: channels of the temporal convolutions;
    ``prefix_p``: the training probability of a cut (`RandomPrefix`); ``dropout`` before the
    last layer.
    """

    task = "sequence"

    def __init__(
        self,
        num_classes: int = 8,
        in_channels: int = 1,
        width: float = 0.5,
        hidden: int = 128,
        prefix_p: float = 0.5,
        dropout: float = 0.3,
        keypoints: bool = True,
    ) -> None:
        super().__init__()
        self.num_classes, self.in_channels = num_classes, in_channels
        self.prefix = RandomPrefix(prefix_p)
        self.trunk = FrameFeatures(2 * in_channels, width, keypoints)
        self.temporal = nn.Sequential(
            CausalConv1d(self.trunk.size, hidden, 3, 1),
            nn.BatchNorm1d(hidden),
            nn.ReLU(inplace=True),
            CausalConv1d(hidden, hidden, 3, 2),
            nn.BatchNorm1d(hidden),
            nn.ReLU(inplace=True),
        )
        self.head = nn.Sequential(nn.Dropout(dropout), nn.Linear(hidden, num_classes))
        init_weights(self)
        _init_temporal(self)
        nn.init.zeros_(self.head[-1].weight)  # every press starts at even odds

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, T, C, h, w)`` → ``(B, num_classes)`` logits."""
        check_sequence(x, self.in_channels, "ActionTCN")
        x = self.prefix(x)
        b, t = x.shape[:2]
        change = x - torch.cat([torch.zeros_like(x[:, :1]), x[:, :-1]], 1)
        frames = torch.cat([x, change], 2).flatten(0, 1)
        lit = frames.flatten(1).amax(1) > 0  # a blank, unchanged frame has zero features
        features = frames.new_zeros(b * t, self.trunk.size)
        if lit.any():
            features[lit] = self.trunk(frames[lit]).to(features.dtype)
        features = features.unflatten(0, (b, t))
        return self.head(self.temporal(features.transpose(1, 2)).amax(2))


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
        _init_temporal(self)
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
