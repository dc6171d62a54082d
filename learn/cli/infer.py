"""`handskin predict` (one sample, image or taxel frame) and `handskin stream` (a stream of
frames, one JSON answer each)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from learn.cli.options import ClfOpt, SegOpt, ThreadsOpt, TtaOpt, fail, opt
from tactile.errors import ConfigError, DataError, HandskinError, require_positive
from tactile.files import atomic_path, os_error_text, require_output

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")
FRAME_SUFFIXES = (".csv", ".npy")


def predict_command(
    source: Annotated[
        Path,
        typer.Argument(
            metavar="SOURCE",
            help="A dataset folder (with --sample), a tactile image (.png/.jpg) or a taxel frame "
            "(.csv/.npy, N taxel or C channel values, with --map).",
        ),
    ],
    sample: opt(int | None, "Sample of the dataset (0-based).") = None,
    map_: opt(
        Path | None,
        "For a frame: a dataset (values are raw counts) or a layout file (Pa).",
        "--map",
    ) = None,
    classifier: ClfOpt = None,
    segmenter: SegOpt = None,
    png: opt(
        Path | None, "Write the prediction figure here (PNG) and <stem>_parts.png beside it."
    ) = None,
    out: opt(
        Path | None, "Write the per-taxel predicted classes here (.npy, (N,) uint8 0..6)."
    ) = None,
    step_mm: opt(float, "Grid step of a map built from a layout file, mm/pixel.") = 1.0,
    threshold_pa: opt(float | None, "Per-part counts take taxels above this pressure, Pa.") = None,
    tta: TtaOpt = False,
    int8: opt(
        bool, "The classifier (HandsNet) as int8; the segmenter stays float.", "--int8"
    ) = False,
    calibration: opt(
        Path | None, "For --int8: data whose train split sets the 8-bit ranges."
    ) = None,
) -> None:
    """Class and probability, segmentation, per-taxel labels, per-part taxels and pressure."""
    from learn.infer import predict as P  # optional: torch (the learn extra)

    try:
        kind = _check_predict(source, sample, map_, classifier, segmenter, out, int8, calibration)
        if threshold_pa is not None and not threshold_pa >= 0:
            raise ConfigError(f"--threshold-pa {threshold_pa}: give a pressure >= 0 Pa")
        require_positive("--step-mm", step_mm, "mm/pixel")
        reads = [source, map_, *(classifier or ()), *(segmenter or ()), calibration]
        require_output(out, "--out", reads=reads, suffixes=(".npy",))
        parts = [png.with_name(f"{png.stem}_parts.png")] if png is not None else []
        require_output(png, "--png", reads=reads, suffixes=(".png",), derived=parts)
        loaded = None if kind != "dataset" else P.read_sample(source, sample)
        if loaded is not None and threshold_pa is not None:
            loaded = dataclasses.replace(loaded, threshold_pa=threshold_pa)
        clf = None if not classifier else P.load_predictor(_one(classifier), tta, int8, calibration)
        seg = None if not segmenter else P.load_predictor(_one(segmenter), tta)
        if kind == "dataset":
            pred = P.predict_sample(loaded, clf, seg)
        elif kind == "image":
            pred = P.predict_image(P.load_image(source), clf, seg)
        else:
            tmap, layout, to_pa = P.load_map(map_, step_mm)
            frame = to_pa(P.read_frame(source, layout, to_pa))  # raw counts checked
            pred = P.predict_frame(frame, tmap, clf, seg, threshold_pa or 0.0)
    except (HandskinError, KeyError) as err:
        raise fail(err) from err
    if pred.class_name is not None:
        typer.echo(f"class {pred.class_name} (probability {pred.probability:.4f})")
    for name, s in (pred.parts or {}).items():
        typer.echo(f"{name:7s} {s.n_taxels:5d} taxels, mean pressure {s.mean_pressure:.4g} Pa")
    _echo_contacts(pred)
    try:
        _write_prediction(P, pred, out, png, seg and segmenter)
    except OSError as err:  # a full disk; each file is written whole or not at all
        raise fail(ValueError(os_error_text(err))) from err


def _echo_contacts(pred) -> None:
    """One line per separate contact when a frame holds several: its taxels and hand parts."""
    n = int(pred.contacts.max(initial=0)) if pred.contacts is not None else 0
    for k in range(1, n + 1) if n > 1 else ():
        taxels = int((pred.contacts == k).sum())
        parts = (pred.contact_parts or [{}] * n)[k - 1]
        pressed = ", ".join(f"{name} {s.n_taxels}" for name, s in parts.items() if s.n_taxels)
        typer.echo(f"contact {k}: {taxels} taxels" + (f"; {pressed}" if pressed else ""))


def _write_prediction(P, pred, out: Path | None, png: Path | None, segmenter) -> None:
    """Write ``handskin predict``'s per-taxel labels (.npy) and figures, each atomically."""
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        with atomic_path(out, keep_suffix=True) as tmp:
            np.save(tmp, pred.taxel_labels.astype(np.uint8))
        typer.echo(f"per-taxel labels written to {out}")
    if png is not None:
        name = f"predicted ({' + '.join(p.parent.name for p in segmenter)})" if segmenter else ""
        for path in P.save_figures(pred, png, name or "predicted"):
            typer.echo(f"picture written to {path}")


def stream_command(
    map_: opt(
        Path, "The skin's dataset (frames are raw counts) or layout file (frames in Pa).", "--map"
    ),
    classifier: ClfOpt = None,
    segmenter: SegOpt = None,
    zmq: opt(str | None, "Read frames from this ZeroMQ address (PULL, bound), not stdin.") = None,
    zmq_out: opt(
        str | None, "Send answers to this ZeroMQ address (PUSH, bound), not stdout."
    ) = None,
    period_ms: opt(
        float, "Frame period, ms: an answer later than this after its frame is late."
    ) = 100.0,
    latest: opt(
        bool, "Of the frames waiting, answer the newest; the others count as dropped.", "--latest"
    ) = False,
    labels: opt(bool, "Per-taxel labels in each answer.", "--labels/--no-labels") = True,
    int8: opt(bool, "The classifier (HandsNet) as int8.", "--int8") = False,
    calibration: opt(
        Path | None, "For --int8: data whose train split sets the 8-bit ranges."
    ) = None,
    bf16: opt(
        bool,
        "The segmenter's weights in bfloat16 (AVX512-BF16, AMX): faster, near ties change.",
        "--bf16",
    ) = False,
    compile_nets: opt(
        bool,
        "Compile the networks but int8 for single frames (TorchInductor, seconds).",
        "--compile",
    ) = False,
    threshold_pa: opt(float, "Per-part counts take taxels above this pressure, Pa.") = 0.0,
    step_mm: opt(float, "Grid step of a map built from a layout file, mm/pixel.") = 1.0,
    threads: ThreadsOpt = 1,
) -> None:
    """Recognise a stream of frames: one JSON answer per frame (docs/learning.md, Stream).

    Exit status 0 when every frame was answered, 1 when some were answered with an error, 2
    when the options are refused."""
    from learn.infer import serve as S  # optional: torch (the learn extra)

    try:
        for path in [*(classifier or ()), *(segmenter or ())]:
            if not path.is_file():
                raise DataError(
                    f"no checkpoint at {path}. Fix: give a .pt file from handskin train"
                )
        if not threshold_pa >= 0:
            raise ConfigError(f"--threshold-pa {threshold_pa}: give a pressure >= 0 Pa")
        require_positive("--step-mm", step_mm, "mm/pixel")
        rec, decode = S.load_recognizer(
            map_,
            classifier and _one(classifier),
            segmenter and _one(segmenter),
            int8,
            calibration,
            compile_nets,
            bf16,
            threshold_pa,
            step_mm,
            threads,
        )
        stats = S.run_stream(rec, decode, S.StreamOptions(zmq, zmq_out, period_ms, latest, labels))
    except (HandskinError, KeyError) as err:
        raise fail(err) from err
    typer.echo(stats.summary(), err=True)
    if stats.errors:  # each was answered with its error line; the exit status says so too
        raise typer.Exit(1)


def _one(paths: list[Path]) -> Path | list[Path]:
    return paths[0] if len(paths) == 1 else paths


def _check_predict(source, sample, map_, clf, seg, out, int8, calibration) -> str:
    """The kind of ``handskin predict``'s input ("dataset", "image" or "frame") and its options'
    combinations, checked before any work."""
    dataset = (source / "dataset.h5").is_file()
    suffix = source.suffix.lower()
    if not dataset and not source.is_file():
        raise DataError(f"no dataset folder or file at {source}")
    kind = "dataset" if dataset else "image" if suffix in IMAGE_SUFFIXES else "frame"
    if kind == "frame" and suffix not in FRAME_SUFFIXES:
        raise DataError(
            f"{source}: give a dataset folder, an image ({', '.join(IMAGE_SUFFIXES)}) or a "
            "frame (.csv, .npy)"
        )
    if (kind == "dataset") != (sample is not None):
        raise ConfigError("--sample N goes with a dataset folder (and only with one)")
    if (kind == "frame") != (map_ is not None):
        raise ConfigError("--map goes with a taxel frame: the dataset or layout file it belongs to")
    if not clf and not seg:
        raise ConfigError("give --classifier, --segmenter or both")
    for path in [*(clf or ()), *(seg or ())]:
        if not path.is_file():
            raise DataError(f"no checkpoint at {path}. Fix: give a .pt file from handskin train")
    if out is not None and (not seg or kind == "image" or out.suffix != ".npy"):
        raise ConfigError(
            "--out writes per-taxel labels (.npy): it needs --segmenter and a dataset or frame"
        )
    if calibration is not None and not int8:
        raise ConfigError("--calibration sets the ranges of the int8 classifier; add --int8")
    if int8 and not clf:
        raise ConfigError("--int8 makes the classifier (HandsNet) 8-bit; give --classifier")
    return kind
