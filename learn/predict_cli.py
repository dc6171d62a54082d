"""`handskin predict`: classify and segment one sample, frame or image (Figs. 12-13, 18).

Inputs are checked before any work; errors print ``error: <what and how to fix>`` and exit
with status 2.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Annotated

import typer

from learn.cli import _fail, _opt
from tactile.errors import ConfigError, HandskinError

ImageOpt = _opt(
    Path | None,
    "A tactile image file (grey PNG/JPG, any size in pixels; taken "
    "as 1 mm per pixel by a model with an input canvas).",
)
FrameOpt = _opt(Path | None, "A taxel frame (.csv row or .npy) of N taxel or C channel values.")
MapOpt = _opt(
    Path | None,
    "For --frame: a dataset folder (its map; values are raw counts, "
    "converted to Pa) or a layout file (values taken as Pa).",
    "--map",
)
PredDataOpt = _opt(
    Path | None,
    "A dataset folder: predict its sample --index (the stored "
    "image; raw counts converted to Pa; the ground truth shown when stored).",
)
IndexOpt = _opt(int | None, "Sample of --data (count, 0-based).")
ClfOpt = Annotated[
    list[Path] | None,
    typer.Option(
        metavar="<path>",
        help=(
            "Classifier checkpoint (.pt file); give it again to average several networks' "
            "softmax (an ensemble, about the sum of their times)."
        ),
    ),
]
SegOpt = Annotated[
    list[Path] | None,
    typer.Option(
        metavar="<path>",
        help=(
            "Segmenter checkpoint (.pt file); give it again to average several networks' "
            "softmax (an ensemble, about the sum of their times)."
        ),
    ),
]
PngOpt = _opt(
    Path | None,
    "Write the Figs. 12-13 figure here (PNG, 90 dpi: image, truth when "
    "known, prediction, errors in red) and Fig. 18's per-part bars (kPa, taxel "
    "count) beside it as <stem>_parts.png.",
)
LabelsOpt = _opt(
    Path | None,
    "Write the per-taxel predicted class ids here (.npy, (N,) uint8 "
    "0..6, no unit) for: handskin view DATASET --sample I --color prediction "
    "--pred FILE.npy.",
)
StepOpt = _opt(float, "Grid step of the map built from a layout file, mm/pixel.")
ThresholdOpt = _opt(
    float | None,
    "Per-part counts and means take taxels above this pressure, "
    "Pa (default: the dataset's active-taxel threshold for --data, else 0).",
)
PredTtaOpt = _opt(
    bool,
    "Test-time flips: each network's mean softmax over the views it was "
    "trained on (original, columns and rows reversed); about 3x the time.",
    "--tta",
)
PredInt8Opt = _opt(
    bool,
    "The classifier (HandsNet) as its 8-bit integer copy (learn.quantize: "
    "about 1.6x faster on an AVX2 CPU), calibrated on 512 training images of "
    "--calibration or of the data it was trained on; the segmenter stays float.",
    "--int8",
)
CalibrationOpt = _opt(
    Path | None,
    "For --int8: a dataset or image folder of the same skin "
    "whose train split sets the 8-bit ranges (default: the classifier "
    "checkpoint's training data).",
)


def predict_command(
    image: ImageOpt = None,
    frame: FrameOpt = None,
    map_: MapOpt = None,
    data: PredDataOpt = None,
    index: IndexOpt = None,
    classifier: ClfOpt = None,
    segmenter: SegOpt = None,
    png: PngOpt = None,
    save_labels: LabelsOpt = None,
    step_mm: StepOpt = 1.0,
    threshold_pa: ThresholdOpt = None,
    tta: PredTtaOpt = False,
    int8: PredInt8Opt = False,
    calibration: CalibrationOpt = None,
) -> None:
    """Class + probability, segmentation, per-taxel labels, per-part taxels and mean pressure.

    Figs. 12-13 and 18 pictures with --png; labels for handskin view with --save-labels."""
    import numpy as np

    from learn import predict as P

    try:
        P.check_inputs(image, frame, map_, data, index, classifier, segmenter, save_labels)
        _check_int8(int8, calibration, classifier)
        if threshold_pa is not None and not threshold_pa >= 0:
            raise ConfigError(f"--threshold-pa {threshold_pa}: give a pressure >= 0 Pa")
        sample = None if data is None else P.read_sample(data, index)
        if sample is not None and threshold_pa is not None:
            sample = dataclasses.replace(sample, threshold_pa=threshold_pa)
        clf = _predictor(P, classifier, tta, int8, calibration)
        seg = _predictor(P, segmenter, tta)
        pred = _predict(P, image, frame, map_, sample, clf, seg, step_mm, threshold_pa or 0.0)
    except (HandskinError, KeyError) as err:
        raise _fail(err) from err
    _echo_prediction(pred)
    if save_labels is not None:
        save_labels.parent.mkdir(parents=True, exist_ok=True)
        np.save(save_labels, pred.taxel_labels.astype(np.uint8))
        typer.echo(f"per-taxel labels written to {save_labels}")
    if png is not None:
        folders = " + ".join(p.parent.name or "model" for p in segmenter or ())
        name = "predicted" if seg is None else f"predicted ({folders})"
        for path in P.save_figures(pred, png, name):
            typer.echo(f"picture written to {path}")


def _check_int8(int8: bool, calibration: Path | None, classifier: list[Path] | None) -> None:
    """``--int8`` / ``--calibration`` combinations, before any work."""
    if calibration is not None and not int8:
        raise ConfigError("--calibration sets the ranges of the int8 classifier; add --int8")
    if int8 and not classifier:
        raise ConfigError(
            "--int8 makes the classifier (HandsNet) 8-bit; give --classifier "
            "(the segmenters run in float)"
        )


def _predictor(
    P, paths: list[Path] | None, tta: bool, int8: bool = False, calibration: Path | None = None
):
    """None, one network, or the mean softmax of several (``--segmenter`` given twice)."""
    if not paths:
        return None
    return P.load_predictor(paths[0] if len(paths) == 1 else paths, tta, int8, calibration)


def _predict(P, image, frame, map_, sample, clf, seg, step_mm, threshold_pa):
    if sample is not None:
        return P.predict_sample(sample, clf, seg)
    if image is not None:
        return P.predict_image(P.load_image(image), clf, seg)
    tmap, layout, to_pa = P.load_map(map_, step_mm)
    return P.predict_frame(to_pa(P.read_frame(frame, layout)), tmap, clf, seg, threshold_pa)


def _echo_prediction(pred) -> None:
    if pred.class_name is not None:
        typer.echo(f"class {pred.class_name} (probability {pred.probability:.4f})")
    if pred.parts is not None:
        for name, s in pred.parts.items():
            typer.echo(f"{name:7s} {s.n_taxels:5d} taxels, mean pressure {s.mean_pressure:.4g}")
