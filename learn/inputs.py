"""Network inputs from tactile images, one rule for training, evaluation, prediction and the
experiments, and the flipped views the networks are trained and tested in (torch-free: numpy
arrays, or torch tensors where said)."""

from __future__ import annotations

import numpy as np

from tactile.images.resize import canvas_px, fit_canvas, resize_grey, resize_labels

#: The rule of `net_input`, stored in every checkpoint (``learn.train.checkpoint``): segmentation
#: inputs on their labels' support since this name; a segmenter without it was trained on
#: inputs blurred past that support and is refused.
INPUTS = "segment-on-label-support"


#: Axes each view reverses on a (..., H, W) array: 0 original, 1 columns (a horizontal flip),
#: 2 rows (a vertical flip), 3 both (a 180-degree turn).
VIEW_DIMS: dict[int, tuple[int, ...]] = {0: (), 1: (-1,), 2: (-2,), 3: (-2, -1)}

#: The paper's threefold augmentation: original, columns reversed, rows reversed.
PAPER_VIEWS: tuple[int, ...] = (0, 1, 2)


#: Class-name suffixes of mirror pairs (`mirror_classes`): a mirrored view turns a clockwise
#: twist into a counter-clockwise one, a push to the left into one to the right.
MIRROR_SUFFIXES: tuple[tuple[str, str], ...] = (("_cw", "_ccw"), ("_left", "_right"))


def is_mirror(view: int) -> bool:
    """True for a view that mirrors the map (one axis reversed), False for the original and the
    180-degree turn, which keep the sense of turns and of left and right."""
    return len(VIEW_DIMS[int(view)]) == 1


def mirror_classes(names) -> np.ndarray | None:
    """(C,) int64: the class each of ``names`` becomes in a mirrored view (`is_mirror`), the
    mirror pairs found by `MIRROR_SUFFIXES` (``push_left`` and ``push_right``); None when every
    class stays itself (hand / non-hand, hand parts)."""
    names = list(names)
    out = np.arange(len(names), dtype=np.int64)
    for i, name in enumerate(names):
        for a, b in MIRROR_SUFFIXES:
            for mine, theirs in ((a, b), (b, a)):
                if name.endswith(mine) and name[: -len(mine)] + theirs in names:
                    out[i] = names.index(name[: -len(mine)] + theirs)
    return None if (out == np.arange(len(names))).all() else out


def targets_in_view(y, view: int, mirror=None):
    """Targets ``y`` of images shown in view ``view``: label images (..., H, W) flipped as the
    images are; class ids (S,) swapped to their mirror classes under a mirrored view when
    ``mirror`` (`mirror_classes`, same array type as ``y``) is given, else unchanged."""
    if y.ndim >= 2:
        return flip_view(y, view)
    return mirror[y] if mirror is not None and is_mirror(view) else y


def flip_view(x, view: int):
    """``x`` (..., H, W), a numpy array (as a strided view, no copy) or a torch tensor, in view
    ``view`` (`VIEW_DIMS`); a flip is its own inverse."""
    dims = VIEW_DIMS[int(view)]
    if not dims:
        return x
    return np.flip(x, dims) if isinstance(x, np.ndarray) else x.flip(dims)


def net_input(
    grey: np.ndarray, size: tuple[int, int], task: str, canvas: tuple[int, int] | None = None
) -> np.ndarray:
    """Network input of tactile image(s) (H, W) or (B, H, W) uint8 grey levels: the
    anti-aliased resize to ``size`` (h, w) px, scaled to [0, 1] float32
    (`tactile.images.resize.resize_grey`: the same bytes on any CPU and on the frame path); for
    ``task == "segment"`` kept on the support its nearest-neighbour labels have
    (``keep_support``), so that zero input is background in the labels too. ``canvas`` (H', W')
    map pixels (`input_canvas`): centred on it first (`tactile.images.resize.fit_canvas`). Same
    shape as ``grey`` with (h, w) last."""
    if canvas is not None:
        grey = fit_canvas(grey, canvas)
    return resize_grey(grey, size, keep_support=task == "segment")


def net_labels(
    labels: np.ndarray, size: tuple[int, int], canvas: tuple[int, int] | None = None
) -> np.ndarray:
    """Label image(s) (H, W) or (B, H, W) at the network's (h, w): centred on ``canvas`` (map
    pixels) when given, then the nearest-neighbour resize (`tactile.images.resize.resize_labels`).
    Same dtype."""
    if canvas is not None:
        labels = fit_canvas(labels, canvas)
    return resize_labels(labels, size)


def labels_on_map(
    labels: np.ndarray, shape: tuple[int, int], canvas: tuple[int, int] | None = None
) -> np.ndarray:
    """The way back of `net_labels`: network labels (h, w) to the map's (H, W) pixels, through
    ``canvas`` (H', W') map pixels when the model has one (nearest neighbour, then off the
    canvas). Same dtype."""
    if canvas is None:
        return resize_labels(labels, shape)
    return fit_canvas(resize_labels(labels, canvas), shape)


def input_canvas(canvas_mm: tuple[float, float] | None, step_mm: float) -> tuple[int, int] | None:
    """Map pixels (H', W') of a model's ``canvas_mm`` (``ModelConfig``) on a map grid of
    ``step_mm`` mm per pixel; None stays None (stretch each map to the input)."""
    return None if canvas_mm is None else canvas_px(canvas_mm, step_mm)


def unpressed_as_background(pred, x):
    """Per-pixel class ids ``pred`` (S, h, w) with every pixel whose input ``x`` (S, 1, h, w) is
    0 set to background (0): no pressure, no contact. With `net_input`'s segmentation inputs
    those are exactly the pixels the labels call background for want of pressure, and
    ``learn.infer.predict.segment`` applies the same rule on the map grid. Median-frequency weights
    make a background pixel ~50x cheaper to miss than a finger's, so without the rule a
    segmenter paints fingers on the empty pixels around a print (95,000 of them on the forearm
    test set, 44.2 % against 53.5 % mIoU). numpy arrays or torch tensors; same type back."""
    return pred * (x[:, 0] > 0)
