"""The networks of learn/ and their registry: ``create_model(arch, **kw)``.

Every model takes ``(B, in_channels, H, W)`` float images in [0, 1] and returns logits:
classifiers ``(B, num_classes)``, segmenters ``(B, num_classes, H, W)`` at the input size.
Each exposes ``num_classes``, ``in_channels`` and ``task`` ("classification" / "segmentation");
the action networks (``task = "sequence"``) take sequences ``(B, T, in_channels, H, W)``.
"""

from __future__ import annotations

import copy
from collections.abc import Callable

import torch
from torch import nn

import learn.numerics  # noqa: F401 (torch's worker threads start flushing subnormals)
from learn.models.action import Action3D
from learn.models.blocks import fold_batch_norm
from learn.models.compact import CompactSeg, HandParts
from learn.models.fcn import FCN16s
from learn.models.handsnet import HandsNet
from learn.models.segnet import SegNet
from learn.models.vgg import VGGClassifier, VGGEncoder, load_vgg_weights

#: Registered architectures: name → constructor.
MODELS: dict[str, Callable[..., nn.Module]] = {
    "handsnet": HandsNet,
    "vgg16": VGGClassifier,
    "segnet": SegNet,
    "fcn16s": FCN16s,
    "action_3d": Action3D,
    "compactseg": CompactSeg,
    "handparts": HandParts,
}


def create_model(arch: str, **kwargs: object) -> nn.Module:
    """Build the registered architecture ``arch`` with the constructor's keyword arguments.

    Raises ``KeyError`` listing the registered names when ``arch`` is unknown.
    """
    try:
        constructor = MODELS[arch]
    except KeyError:
        raise KeyError(
            f"unknown architecture {arch!r}; choose one of: {', '.join(sorted(MODELS))}"
        ) from None
    return constructor(**kwargs)


def count_parameters(model: nn.Module, *, trainable_only: bool = False) -> int:
    """Number of parameters (all, or only those with ``requires_grad``)."""
    return sum(p.numel() for p in model.parameters() if p.requires_grad or not trainable_only)


def prepare_for_inference(model: nn.Module) -> nn.Module:
    """A copy of ``model`` for fast CPU inference: eval mode, batch norms folded into the convs,
    channels-last memory format. Same outputs as ``model.eval()`` up to float rounding.
    """
    prepared = fold_batch_norm(copy.deepcopy(model).eval())
    return prepared.to(memory_format=torch.channels_last)


__all__ = [
    "MODELS",
    "Action3D",
    "CompactSeg",
    "FCN16s",
    "HandParts",
    "HandsNet",
    "SegNet",
    "VGGClassifier",
    "VGGEncoder",
    "count_parameters",
    "create_model",
    "load_vgg_weights",
    "prepare_for_inference",
]
