"""Network inputs from tactile images, one rule for training, evaluation, prediction and the
experiments (torch-free, so the robustness experiments' frame code can use it too)."""

from __future__ import annotations

import numpy as np

from tactile.resize import resize_image

#: The rule of `net_input`, stored in every checkpoint (``learn.checkpoint``): segmentation
#: inputs on their labels' support since this name; a segmenter without it was trained on
#: inputs blurred past that support and is refused.
INPUTS = "segment-on-label-support"


def net_input(image01: np.ndarray, size: tuple[int, int], task: str) -> np.ndarray:
    """Network input of image(s) (H, W) or (B, H, W) float scaled to [0, 1]: the anti-aliased
    resize to ``size`` (h, w) px; for ``task == "segment"`` kept on the support its nearest-
    neighbour labels have (`tactile.resize.resize_image` ``keep_support``), so that zero input
    is background in the labels too. Same shape as ``image01`` with (h, w) last, same dtype."""
    return resize_image(image01, size, keep_support=task == "segment")


def unpressed_as_background(pred, x):
    """Per-pixel class ids ``pred`` (S, h, w) with every pixel whose input ``x`` (S, 1, h, w) is
    0 set to background (0): no pressure, no contact. With `net_input`'s segmentation inputs
    those are exactly the pixels the labels call background for want of pressure, and
    ``learn.predict.segment`` applies the same rule on the map grid. Median-frequency weights
    make a background pixel ~50x cheaper to miss than a finger's, so without the rule a
    segmenter paints fingers on the empty pixels around a print (95,000 of them on the forearm
    test set, 44.2 % against 53.5 % mIoU). numpy arrays or torch tensors; same type back."""
    return pred * (x[:, 0] > 0)
