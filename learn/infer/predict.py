"""Prediction from a dataset sample, a taxel frame or a tactile image: hand / non-hand class and
probability, hand-part segmentation, per-taxel labels back-projected through the map, per-part
taxel count and mean pressure (the paper's Fig. 18), and pictures: the Figs. 12–13 prediction
figure (errors in red when the ground truth is known) and the Fig. 18 per-part bars.

    clf, seg = load_predictor("runs/handsnet/best.pt"), load_predictor("runs/segnet/best.pt")
    pred = predict_sample(read_sample("out/forearm", 12), clf, seg)     # ground truth attached
    tmap, layout, to_pa = load_map("out/forearm")            # a dataset folder or a layout file
    pred = predict_frame(to_pa(read_frame("frame.csv", layout, to_pa)), tmap, clf, seg)
    pred.class_name, pred.probability, pred.parts["index"].n_taxels, pred.taxel_labels
    save_figures(pred, "pred.png")                   # pred.png and pred_parts.png

Per-taxel labels follow `tactile.images.labels.backproject`: a taxel takes the most frequent hand
part among the segmented pixels within 2 pixels (2 · step_mm) of it on the map, background if none.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from matplotlib.figure import Figure

from learn.data.folder import HAND_NAMES, read_grey
from learn.data.load import is_dataset
from learn.infer.ensemble import FlipTTA, MeanSoftmax, load_members, tta_views
from learn.infer.fastpath import fast_inference
from learn.infer.int8_file import int8_from_checkpoint
from learn.inputs import input_canvas, labels_on_map, net_input
from learn.numerics import flushing
from learn.train.checkpoint import is_int8, load_checkpoint, model_from_checkpoint
from tactile.dataset.reader import DatasetReader
from tactile.dataset.readout import MAX_COUNT, count_fault
from tactile.errors import ConfigError, DataError
from tactile.geometry.layout import TaxelLayout
from tactile.images.labels import PartSummary, backproject, contact_instances, part_summary
from tactile.images.tactile_map import TactileMap


@dataclass
class Predictor:
    """A trained network on the fast inference path, with its input size and class names."""

    model: torch.nn.Module
    task: str  # "classify" | "segment" | "both" (class and parts in one pass)
    input_size: tuple[int, int]  # (h, w) px of the network input
    class_names: tuple[str, ...]
    canvas_mm: tuple[float, float] | None = None  # ModelConfig.canvas_mm: (H, W) mm, or None

    def canvas(self, step_mm: float) -> tuple[int, int] | None:
        """(H', W') map pixels of the model's canvas on a grid of ``step_mm`` mm, or None."""
        return input_canvas(self.canvas_mm, step_mm)

    def logits(self, image: np.ndarray, step_mm: float = 1.0):
        """Logits of one (H, W) uint8 image on a map grid of ``step_mm`` mm per pixel (used
        only with a canvas), made into the network input: (C,) or (C, h, w); for a
        class-and-parts network the pair ((2,), (C, h, w))."""
        task = "classify" if self.task == "classify" else "segment"
        x = net_input(np.asarray(image, np.uint8), self.input_size, task, self.canvas(step_mm))
        with torch.inference_mode(), flushing():
            out = self.model(torch.from_numpy(x)[None, None])
        return tuple(o[0].float() for o in out) if isinstance(out, tuple) else out[0].float()


def load_predictor(
    path: str | Path | Sequence[str | Path],
    tta: bool = False,
    int8: bool = False,
    calibration: str | Path | None = None,
) -> Predictor:
    """A checkpoint written by ``handskin train``, ready for fast CPU inference; ``tta``: with
    test-time flips over the views it was trained on (`learn.infer.ensemble.FlipTTA`; its
    logits are then the log of the mean softmax). Several checkpoints of one task make an
    ensemble (`learn.infer.ensemble.MeanSoftmax`), checked alike (task, classes, input size)
    before any work. ``int8`` (HandsNet only): each network as its 8-bit copy, calibrated on the
    train split of ``calibration`` or of the data it was trained on. An int8 file (``handskin
    quantize``) always runs as its saved int8 network."""
    if isinstance(path, str | Path):
        ckpt = load_checkpoint(path)
        model, run = model_from_checkpoint(ckpt, int8_ok=True, where=path)
        members = [(Path(path), ckpt, model, run)]
    else:
        members = [(m.path, m.ckpt, m.model, m.run) for m in load_members(path, int8_ok=True)]
    nets = []
    for where, ckpt, model, run in members:
        if run.task == "action":
            raise ConfigError(
                f"{where} is an action network: it names the action of a whole press from its "
                "sequence of frames, not the class of one image. Fix: give a classifier or "
                "segmenter here; score the action network with handskin evaluate"
            )
        fast = (
            int8_from_checkpoint(model, run, ckpt, calibration)
            if int8 or is_int8(ckpt)
            else fast_inference(model)
        )
        nets.append(FlipTTA(fast, tta_views(run, where)) if tta else fast)
    _, ckpt, _, run = members[0]
    names = tuple(ckpt.get("class_names") or ())
    net = nets[0] if len(nets) == 1 else MeanSoftmax(nets)
    return Predictor(net, run.task, run.model.input_size, names, run.model.canvas_mm)


@dataclass
class Prediction:
    """Everything ``predict_*`` found. Images (H, W) on the map grid (or the input image's)."""

    image: np.ndarray  # (H, W) uint8 tactile image
    class_name: str | None = None  # most probable class (classifier given)
    probability: float | None = None  # its softmax probability, in [0, 1]
    segmentation: np.ndarray | None = None  # (H, W) uint8 classes 0..6 (segmenter given)
    taxel_labels: np.ndarray | None = None  # (N,) uint8 classes (frame and segmenter given)
    pressure: np.ndarray | None = None  # (N,) float, the frame's pressures, Pa
    parts: dict[str, PartSummary] | None = None  # per hand part: taxels pressed, mean pressure
    true_segmentation: np.ndarray | None = None  # (H, W) uint8 ground truth (dataset sample)
    true_labels: np.ndarray | None = None  # (N,) uint8 ground-truth taxel classes (dataset)
    threshold_pa: float = 0.0  # a taxel counts as pressed in ``parts`` above this pressure, Pa
    contacts: np.ndarray | None = None  # (N,) int64 contact of each pressed taxel, 0 none, 1..K
    contact_parts: list[dict[str, PartSummary]] | None = None  # per contact, like ``parts``


def classify(pred: Prediction, clf: Predictor, step_mm: float = 1.0) -> None:
    """Fill ``class_name`` and ``probability`` from a classifier (``step_mm``: the image's
    grid, mm per pixel)."""
    logits = clf.logits(pred.image, step_mm)
    probs = (logits[0] if clf.task == "both" else logits).softmax(0)
    k = int(probs.argmax())
    names = HAND_NAMES if clf.task == "both" else clf.class_names
    pred.class_name = names[k] if k < len(names) else str(k)
    pred.probability = float(probs[k])


def segment(image: np.ndarray, seg: Predictor, step_mm: float = 1.0) -> np.ndarray:
    """(H, W) uint8 classes: the network's labels resized back (and off its canvas, if it has
    one), 0 where the image is 0. ``step_mm``: the image's grid, mm per pixel."""
    logits = seg.logits(image, step_mm)
    labels = (logits[1] if seg.task == "both" else logits).argmax(0).numpy().astype(np.uint8)
    back = labels_on_map(labels, image.shape, seg.canvas(step_mm))
    return np.where(image > 0, back, 0).astype(np.uint8)


def predict_image(
    image: np.ndarray,
    clf: Predictor | None = None,
    seg: Predictor | None = None,
    step_mm: float = 1.0,
) -> Prediction:
    """Class and segmentation of one (H, W) uint8 tactile image on a map grid of ``step_mm``
    mm per pixel (the default map's 1 mm; it matters only to a model with a canvas)."""
    if clf is None and seg is None:
        raise DataError("give a classifier, a segmenter or both")
    if seg is None and clf.task == "both":
        seg = clf  # a class-and-parts network answers both
    pred = Prediction(np.asarray(image, np.uint8))
    if clf is not None:
        classify(pred, clf, step_mm)
    if seg is not None:
        pred.segmentation = segment(pred.image, seg, step_mm)
    return pred


def predict_frame(
    p: np.ndarray,
    tmap: TactileMap,
    clf: Predictor | None = None,
    seg: Predictor | None = None,
    threshold_pa: float = 0.0,
) -> Prediction:
    """Prediction of a taxel frame ``p`` (N,) pressures (Pa) through the map: the tactile image,
    its class / segmentation, per-taxel labels (``backproject``) and ``part_summary`` (taxels
    above ``threshold_pa``, Pa)."""
    p = np.asarray(p, np.float64)
    if p.shape != (tmap.n_taxels,):
        raise DataError(f"frame has shape {p.shape}; the map has {tmap.n_taxels} taxels")
    return attach_taxels(
        predict_image(tmap.image(p), clf, seg, tmap.step_mm), tmap, p, threshold_pa
    )


def attach_taxels(
    pred: Prediction, tmap: TactileMap, p: np.ndarray, threshold_pa: float = 0.0
) -> Prediction:
    """Fill ``pressure`` (N,) Pa, ``contacts`` (the pressed taxels grouped into separate
    contacts, `tactile.images.labels.contact_instances`) and, with a segmentation, ``taxel_labels``
    (back-projected) and ``parts`` (taxels with p > ``threshold_pa`` per predicted part), also
    per contact (``contact_parts``). Returns ``pred``."""
    pred.pressure, pred.threshold_pa = np.asarray(p, np.float64), float(threshold_pa)
    pred.contacts = contact_instances(tmap.positions_m, pred.pressure, threshold=threshold_pa)
    if pred.segmentation is not None:
        pred.taxel_labels = backproject(tmap, pred.segmentation)
        pred.parts = part_summary(pred.taxel_labels, pred.pressure, threshold=threshold_pa)
        pred.contact_parts = [
            part_summary(
                pred.taxel_labels * (pred.contacts == k), pred.pressure, threshold=threshold_pa
            )
            for k in range(1, int(pred.contacts.max(initial=0)) + 1)
        ]
    return pred


@dataclass(frozen=True)
class Sample:
    """One dataset sample as ``predict_sample`` needs it."""

    index: int
    image: np.ndarray  # (H, W) uint8, the stored tactile image (what the networks were fed)
    pressure: np.ndarray  # (N,) float64, Pa, from the raw readings (``pressure_from_raw``)
    tmap: TactileMap
    true_segmentation: np.ndarray | None  # (H, W) uint8 label image, None when not stored
    true_labels: np.ndarray | None  # (N,) uint8 taxel classes, None when not stored
    threshold_pa: float  # the dataset's active-taxel threshold (0 when not recorded), Pa


def read_sample(path: str | Path, index: int) -> Sample:
    """Sample ``index`` (``--sample``) of the dataset at ``path``; DataError when absent or out
    of range."""
    if not is_dataset(path):
        raise DataError(f"no dataset at {path}. Fix: give a folder holding dataset.h5")
    with DatasetReader(path) as ds:
        if not 0 <= index < len(ds):
            raise DataError(
                f"--sample {index} is out of range; {path} has {len(ds)} samples (0..{len(ds) - 1})"
            )
        truth = [
            np.asarray(ds[f][index], np.uint8) if f in ds.fields else None
            for f in ("label_image", "taxel_label")
        ]
        return Sample(
            index,
            np.asarray(ds.image[index], np.uint8),
            ds.pressure_from_raw(ds.raw[index]),
            ds.map,
            *truth,
            ds.active_threshold_pa,
        )


def predict_sample(
    sample: Sample, clf: Predictor | None = None, seg: Predictor | None = None
) -> Prediction:
    """Prediction of a dataset sample (its stored image), ground truth attached; parts count
    the taxels above the dataset's active threshold (``sample.threshold_pa``)."""
    pred = attach_taxels(
        predict_image(sample.image, clf, seg, sample.tmap.step_mm),
        sample.tmap,
        sample.pressure,
        sample.threshold_pa,
    )
    pred.true_segmentation, pred.true_labels = sample.true_segmentation, sample.true_labels
    return pred


def read_frame(
    path: str | Path, layout: TaxelLayout, units: FrameUnits | None = None
) -> np.ndarray:
    """One frame (.npy or .csv, one row; ``#`` comments) of N taxel or C channel values → (N,);
    ``units``: the map's (`load_map`), whose raw counts are checked as given."""
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
    if units is not None:
        units.check(arr, str(path))
    if len(arr) == layout.n_taxels:
        return arr
    if layout.n_channels is not None and len(arr) == layout.n_channels:
        return layout.taxels_from_channels(arr)
    raise DataError(
        f"{path}: {len(arr)} values; the layout has {layout.n_taxels} taxels "
        f"and {layout.n_channels} channels. Fix: one row of either width"
    )


@dataclass(frozen=True)
class FrameUnits:
    """What a map's frames hold, called to turn (N,) taxel values into pressures, Pa: raw
    counts of a dataset's skin (``to_pa``: its readout), or pascals (``to_pa`` None, the map of
    a layout file)."""

    to_pa: Callable[[np.ndarray], np.ndarray] | None = None

    def __call__(self, values: np.ndarray) -> np.ndarray:
        values = np.asarray(values, np.float64)
        return values if self.to_pa is None else np.asarray(self.to_pa(values), np.float64)

    def check(self, values: np.ndarray, where: str = "the frame") -> None:
        """DataError naming the first of ``values`` (finite, as given: taxels or channels) that
        is no raw count, as `handskin ingest` refuses it (`tactile.dataset.readout.count_fault`);
        a map in pascals takes any finite value."""
        fault = None if self.to_pa is None else count_fault(values)
        if fault is not None:
            (i,), rule = fault
            raise DataError(
                f"{where}: value {i} is {values[i]:g}, {rule}; the map's dataset reads raw "
                f"counts. Fix: give raw sensor counts, integers in 0..{MAX_COUNT}"
            )


def load_map(path: str | Path, step_mm: float = 1.0) -> tuple[TactileMap, TaxelLayout, FrameUnits]:
    """(map, layout, units) of a dataset folder (its stored map; frames in raw counts, → Pa with
    its skin attributes) or of a layout file (map built at ``step_mm``; frames in Pa)."""
    path = Path(path)
    if is_dataset(path):
        reader = DatasetReader(path)
        return reader.map, reader.layout, FrameUnits(reader.pressure_from_raw)
    if not path.is_file():
        raise DataError(f"no dataset folder or layout file at {path}")
    layout = TaxelLayout.load(path)
    return TactileMap.build(layout, step_mm=step_mm), layout, FrameUnits()


def load_image(path: str | Path) -> np.ndarray:
    """A tactile image file as (H, W) uint8."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"no image file at {path}")
    return read_grey(path)


def save_figures(pred: Prediction, path: str | Path, name: str = "predicted") -> list[Path]:
    """PNGs (90 dpi): at ``path`` the Figs. 12–13 figure (image | true | predicted | errors in
    red; image | predicted without ground truth; the image alone without a segmentation), and
    with per-taxel labels the Fig. 18 bars at ``<stem>_parts.png``. ``name``: the prediction's
    caption. The classifier's decision is the figure's title."""
    # start-up: tactile.figures.panels loads matplotlib's drawing stack (~1 s), for pictures only
    from tactile.figures.panels import part_bars_figure, prediction_figure, save_figure

    path = Path(path)
    title = (
        ""
        if pred.class_name is None
        else f"classifier: {pred.class_name} (p = {pred.probability:.3f})"
    )
    if pred.segmentation is None:
        fig = _image_figure(pred.image, title)
    else:
        fig = prediction_figure(
            pred.image, pred.true_segmentation, pred.segmentation, title=title, pred_name=name
        )
    out = [save_figure(fig, path, dpi=90)]
    if pred.taxel_labels is not None:
        bars = part_bars_figure(
            pred.true_labels,
            pred.pressure,
            pred_labels=pred.taxel_labels,
            threshold_pa=pred.threshold_pa,
            title=f"taxels above {pred.threshold_pa:g} Pa per hand part; "
            f"hatched: {name}, back-projected",
        )
        out.append(save_figure(bars, path.with_name(f"{path.stem}_parts.png"), dpi=90))
    return out


def _image_figure(image: np.ndarray, title: str) -> Figure:
    """The tactile image (H, W) uint8 alone, ``title`` above (classifier only)."""
    fig = Figure(
        figsize=(13 / 4, 1.0 + 13 / 4 * image.shape[0] / image.shape[1]), layout="constrained"
    )
    ax = fig.subplots()
    ax.imshow(image, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
    ax.set_title(title or "tactile image", fontsize=9)
    ax.set_axis_off()
    return fig
