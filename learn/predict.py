"""Prediction from a tactile image or a taxel frame: hand / non-hand class and probability,
hand-part segmentation, per-taxel labels back-projected through the map, per-part taxel count
and mean pressure (the paper's Fig. 18), and a picture: image | segmentation | per-part bars.

    clf, seg = load_predictor("runs/handsnet/best.pt"), load_predictor("runs/segnet/best.pt")
    tmap, layout, to_pa = load_map("out/forearm")            # a dataset folder or a layout file
    pred = predict_frame(to_pa(read_frame("frame.csv", layout)), tmap, clf, seg)
    pred.class_name, pred.probability, pred.parts["index"].n_taxels
    save_picture(pred, "pred.png")
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from matplotlib.figure import Figure

from learn.checkpoint import load_checkpoint
from learn.evaluate import fast_inference
from learn.folder import is_dataset, read_grey
from tactile.dataset.reader import DatasetReader
from tactile.errors import DataError
from tactile.labels import CLASS_NAMES, PALETTE, PartSummary, backproject, colorize, part_summary
from tactile.layout import TaxelLayout
from tactile.resize import resize_image, resize_labels
from tactile.tactile_map import TactileMap


@dataclass
class Predictor:
    """A trained network on the fast inference path, with its input size and class names."""

    model: torch.nn.Module
    task: str  # "classify" | "segment"
    input_size: tuple[int, int]  # (h, w) px of the network input
    class_names: tuple[str, ...]

    def logits(self, image: np.ndarray) -> torch.Tensor:
        """Logits of one (H, W) uint8 image (resized to the input): (C,) or (C, h, w)."""
        x = resize_image(np.asarray(image, np.float32) / 255.0, self.input_size)
        with torch.inference_mode():
            return self.model(torch.from_numpy(x)[None, None])[0].float()


def load_predictor(path: str | Path) -> Predictor:
    """A checkpoint written by ``handskin train``, ready for fast CPU inference."""
    from learn.checkpoint import model_from_checkpoint

    ckpt = load_checkpoint(path)
    model, run = model_from_checkpoint(ckpt)
    names = tuple(ckpt.get("class_names") or ())
    return Predictor(fast_inference(model), run.task, run.model.input_size, names)


@dataclass
class Prediction:
    """Everything ``predict_*`` found. Images (H, W) on the map grid (or the input image's)."""

    image: np.ndarray  # (H, W) uint8 tactile image
    class_name: str | None = None  # most probable class (classifier given)
    probability: float | None = None  # its softmax probability, in [0, 1]
    segmentation: np.ndarray | None = None  # (H, W) uint8 classes 0..6 (segmenter given)
    taxel_labels: np.ndarray | None = None  # (N,) uint8 classes (frame and segmenter given)
    pressure: np.ndarray | None = None  # (N,) float, the frame's pressures (Pa, or its unit)
    parts: dict[str, PartSummary] | None = None  # per hand part: taxels pressed, mean pressure


def classify(pred: Prediction, clf: Predictor) -> None:
    """Fill ``class_name`` and ``probability`` from a classifier."""
    probs = clf.logits(pred.image).softmax(0)
    k = int(probs.argmax())
    pred.class_name = clf.class_names[k] if k < len(clf.class_names) else str(k)
    pred.probability = float(probs[k])


def segment(image: np.ndarray, seg: Predictor) -> np.ndarray:
    """(H, W) uint8 classes: the network's labels resized back, 0 where the image is 0."""
    labels = seg.logits(image).argmax(0).numpy().astype(np.uint8)
    return np.where(image > 0, resize_labels(labels, image.shape), 0).astype(np.uint8)


def predict_image(image: np.ndarray, clf: Predictor | None = None,
                  seg: Predictor | None = None) -> Prediction:  # fmt: skip
    """Class and segmentation of one (H, W) uint8 tactile image."""
    if clf is None and seg is None:
        raise DataError("give a classifier, a segmenter or both")
    pred = Prediction(np.asarray(image, np.uint8))
    if clf is not None:
        classify(pred, clf)
    if seg is not None:
        pred.segmentation = segment(pred.image, seg)
    return pred


def predict_frame(p: np.ndarray, tmap: TactileMap, clf: Predictor | None = None,
                  seg: Predictor | None = None) -> Prediction:  # fmt: skip
    """Prediction of a taxel frame ``p`` (N,) pressures through the map: the tactile image,
    its class / segmentation, per-taxel labels (``backproject``) and ``part_summary``."""
    p = np.asarray(p, np.float64)
    if p.shape != (tmap.n_taxels,):
        raise DataError(f"frame has shape {p.shape}; the map has {tmap.n_taxels} taxels")
    pred = predict_image(tmap.image(p), clf, seg)
    pred.pressure = p
    if pred.segmentation is not None:
        pred.taxel_labels = backproject(tmap, pred.segmentation)
        pred.parts = part_summary(pred.taxel_labels, p)
    return pred


def read_frame(path: str | Path, layout: TaxelLayout) -> np.ndarray:
    """One frame (.npy or .csv, one row; ``#`` comments) of N taxel or C channel values → (N,)."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"no frame file at {path}")
    try:
        arr = np.load(path) if path.suffix == ".npy" else np.loadtxt(path, delimiter=",", ndmin=2)
    except ValueError as err:
        raise DataError(f"{path}: not a numeric frame ({err})") from err
    arr = np.asarray(arr, np.float64).reshape(-1) if np.asarray(arr).ndim <= 2 else None
    if arr is None or not np.isfinite(arr).all():
        raise DataError(f"{path}: expected one row of finite numbers")
    if len(arr) == layout.n_taxels:
        return arr
    if layout.n_channels is not None and len(arr) == layout.n_channels:
        return layout.taxels_from_channels(arr)
    raise DataError(f"{path}: {len(arr)} values; the layout has {layout.n_taxels} taxels "
                    f"and {layout.n_channels} channels. Fix: one row of either width")  # fmt: skip


def load_map(path: str | Path, step_mm: float = 1.0):
    """(map, layout, to_pressure) of a dataset folder (its stored map; raw counts → Pa with its
    skin attributes) or of a layout file (map built at ``step_mm``; values used as they are)."""
    path = Path(path)
    if is_dataset(path):
        reader = DatasetReader(path)
        return reader.map, reader.layout, reader.pressure_from_raw
    if not path.is_file():
        raise DataError(f"no dataset folder or layout file at {path}")
    layout = TaxelLayout.load(path)
    identity: Callable[[np.ndarray], np.ndarray] = lambda raw: np.asarray(raw, np.float64)  # noqa: E731
    return TactileMap.build(layout, step_mm=step_mm), layout, identity


def load_image(path: str | Path) -> np.ndarray:
    """A tactile image file as (H, W) uint8."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"no image file at {path}")
    return read_grey(path)


def save_picture(pred: Prediction, path: str | Path, unit: str = "Pa") -> Path:
    """PNG: the tactile image | its segmentation | per-part taxel counts (mean pressure noted)."""
    panels = 1 + (pred.segmentation is not None) + (pred.parts is not None)
    fig = Figure(figsize=(4.2 * panels, 3.6), layout="constrained")
    axes = np.atleast_1d(fig.subplots(1, panels))
    title = "tactile image"
    if pred.class_name is not None:
        title += f": {pred.class_name} (p = {pred.probability:.3f})"
    axes[0].imshow(pred.image, cmap="gray", vmin=0, vmax=255)
    axes[0].set_title(title)
    if pred.segmentation is not None:
        axes[1].imshow(colorize(pred.segmentation))
        axes[1].set_title("segmentation")
    if pred.parts is not None:
        _bars(axes[-1], pred.parts, unit)
    for ax in axes[: 1 + (pred.segmentation is not None)]:
        ax.set(xticks=[], yticks=[])
    fig.savefig(path, dpi=100)
    return Path(path)


def _bars(ax, parts: dict[str, PartSummary], unit: str) -> None:
    names = list(parts)
    counts = [parts[n].n_taxels for n in names]
    colours = PALETTE[[CLASS_NAMES.index(n) for n in names]] / 255.0
    bars = ax.bar(names, counts, color=colours, edgecolor="k")
    for bar, n in zip(bars, names, strict=True):
        ax.annotate(f"{parts[n].mean_pressure:.3g}", (bar.get_x() + bar.get_width() / 2,
                    bar.get_height()), ha="center", va="bottom", fontsize=8)  # fmt: skip
    ax.set(ylabel="taxels pressed", title=f"per part (numbers: mean pressure, {unit})")
    ax.tick_params(axis="x", rotation=45)
