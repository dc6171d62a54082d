"""`handskin train`, `evaluate`, `predict`, `stream` and `quantize` (``register(app)`` adds them).

Every input is checked (files exist, configuration valid, architecture known) before any work;
errors print ``error: <what and how to fix>`` and exit with status 2. The modules that need
torch are imported inside the commands: PyTorch is an optional extra (and `handskin --help`
stays fast without it).
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
import json
import shlex
import warnings
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from learn import config as C
from tactile.config import to_dict
from tactile.errors import (
    ConfigError,
    DataError,
    HandskinError,
    require_folder,
    require_positive,
)
from tactile.files import atomic_path, os_error_text, require_writable, write_text_atomic

CLASSICAL = ("bovw", "vgg_svm")  # as learn.classical.svm.CLASSICAL (not imported: fast --help)
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")
FRAME_SUFFIXES = (".csv", ".npy")


def fail(err: Exception) -> typer.Exit:
    """Print ``error: ...`` for a user error and return the exit (status 2) to raise."""
    typer.echo(f"error: {err.args[0] if isinstance(err, KeyError) else err}", err=True)
    return typer.Exit(2)


def opt(kind, help_text: str, *names: str):
    """``Annotated[kind, typer.Option(*names, help=help_text)]``."""
    return Annotated[kind, typer.Option(*names, help=help_text)]


# options shared by the commands of learn/ and the experiments
DataArg = Annotated[
    Path, typer.Argument(metavar="DATASET", help="Dataset folder (dataset.h5) or image folder.")
]
SeedOpt = opt(int | None, "Seed of init, shuffling and splits (integer).")
ThreadsOpt = opt(int, "CPU threads (count).")
DeviceOpt = opt(
    str | None, "Where networks train: cpu (reproducible from the seed), cuda or cuda:N."
)
ProgressOpt = opt(bool, "Show progress bars.", "--progress/--no-progress")
HandOpt = opt(
    str | None, "Image folders: comma-separated folder names that are 'hand'.", "--hand-classes"
)
ClfOpt = Annotated[
    list[Path] | None,
    typer.Option(metavar="PATH", help="Classifier (.pt); given twice or more: their mean softmax."),
]
SegOpt = Annotated[
    list[Path] | None,
    typer.Option(metavar="PATH", help="Segmenter (.pt); given twice or more: their mean softmax."),
]
TtaOpt = opt(bool, "Test-time flips: each network's mean softmax over its training views.", "--tta")


def hand_classes(text: str | None) -> tuple[str, ...] | None:
    """``--hand-classes`` as a tuple of folder names (None when not given)."""
    return None if not text else tuple(t.strip() for t in text.split(",") if t.strip())


def needs_torch(command):
    """``command`` preceded by a clear error when PyTorch is not installed (it is an extra)."""

    @functools.wraps(command)
    def checked(*args, **kwargs):
        if importlib.util.find_spec("torch") is None:
            typer.echo(
                "error: this command needs PyTorch, which handskin installs with its 'learn' "
                "extra. Fix: pip install 'handskin[learn]' (without a GPU, install the CPU "
                "wheel of torch first)",
                err=True,
            )
            raise typer.Exit(2)
        with warnings.catch_warnings():  # a warning is one line for the user, not a source line
            warnings.showwarning = lambda message, *_: typer.echo(f"warning: {message}", err=True)
            return command(*args, **kwargs)

    return checked


def parse_canvas(text: str) -> tuple[float, float]:
    """``--canvas-mm`` 'H,W' (mm) -> (H, W); ConfigError when malformed or not positive."""
    try:
        h, w = (float(t) for t in text.split(","))
    except ValueError:
        h = w = float("nan")
    if not (h > 0 and w > 0):
        raise ConfigError(
            f"--canvas-mm {text!r}: give the canvas as H,W in mm, both > 0, e.g. 229,383"
        )
    return h, w


def _check_data(data: Path) -> None:
    if not (data.is_dir() or (data.is_file() and data.suffix == ".h5")):
        raise DataError(
            f"no dataset or image folder at {data}. Fix: a dataset folder (holding dataset.h5) "
            "or a folder of class sub-folders of images"
        )


def resolve_run(
    arch: str, config: Path | None, changes: dict, test_c: bool, canvas: str | None = None
):
    """The RunConfig: the arch's preset, the TOML file over it, then the command line's."""
    preset = C.PRESET_OF_ARCH[arch]
    run = dataclasses.replace(preset, train=C.FINETUNE_TEST_C) if test_c else preset
    run = C.load_run_config(config, run) if config is not None else run
    top = ("val_fraction", "precision", "device")
    train = {k: v for k, v in changes.items() if v is not None and k not in top}
    run = C.replace_train(run, **train) if train else run
    run = dataclasses.replace(run, **{k: changes[k] for k in top if changes.get(k) is not None})
    if canvas is not None:
        run = dataclasses.replace(
            run, model=dataclasses.replace(run.model, canvas_mm=parse_canvas(canvas))
        )
    return run


def train_command(
    data: DataArg,
    out: opt(Path, "Run folder: best.pt, last.pt, curves.png, run.toml, test_metrics.json."),
    arch: opt(
        str, "handsnet | vgg16 | segnet | fcn16s | action_tcn | action_3d, or bovw | vgg_svm."
    ) = "handsnet",
    config: opt(
        Path | None, "TOML run config laid over the arch's preset (docs/learning.md)."
    ) = None,
    epochs: opt(int | None, "Epochs (passes over every train image in every view).") = None,
    batch_size: opt(int | None, "Images per optimisation step.") = None,
    lr: opt(float | None, "Initial learning rate (per step, dimensionless).") = None,
    seed: SeedOpt = None,
    val_fraction: opt(float | None, "Share (0-1) of the train split's people held out.") = None,
    precision: opt(str | None, "Forward pass number format: fp32 or bf16 (CPUs with AMX).") = None,
    device: DeviceOpt = None,
    hand_names: HandOpt = None,
    init: opt(
        Path | None, "Fine-tune from this checkpoint (.pt): the tensors that fit load."
    ) = None,
    test_c: opt(bool, "The paper's Test C fine-tuning schedule.", "--test-c") = False,
    canvas_mm: opt(str | None, "Input canvas H,W in mm (e.g. 229,383); default: stretch.") = None,
    resume: opt(bool, "Continue the run in OUT from its last.pt.", "--resume") = False,
    stop_after_epoch: opt(int | None, "Stop after this epoch (1-based); --resume goes on.") = None,
    cv_grid: opt(
        str | None, "Cross-validate first: 'train.lr=0.01,0.001;train.batch_size=32'."
    ) = None,
    cv_folds: opt(int, "Folds of the cross-validation (count).") = 5,
    from_scratch: opt(
        bool, "Segmenters: not from a vgg16 classifier's encoder (OUT/vgg16).", "--from-scratch"
    ) = False,
    progress: ProgressOpt = True,
) -> None:
    """Train a network (or a classical baseline) on DATASET's train split; score its test split."""
    hand = hand_classes(hand_names)
    try:
        _check_data(data)
        require_folder(out)
        require_writable(out, "--out", folder=True)
        if arch in CLASSICAL:
            network_only = {"--batch-size": batch_size, "--lr": lr, "--val-fraction": val_fraction}
            network_only |= {"--precision": precision, "--device": device, "--test-c": test_c}
            network_only |= {"--canvas-mm": canvas_mm, "--resume": resume, "--cv-grid": cv_grid}
            network_only |= {"--stop-after-epoch": stop_after_epoch}
            network_only |= {"--from-scratch": from_scratch}
            unused = {k: v or None for k, v in network_only.items()}
            _train_classical(arch, data, out, config, seed, hand, init, epochs, progress, unused)
            return
        if arch not in C.PRESET_OF_ARCH:
            choices = ", ".join((*C.PRESET_OF_ARCH, *CLASSICAL))
            raise ConfigError(f"--arch {arch!r}: choose one of {choices}")
        changes = {"epochs": epochs, "batch_size": batch_size, "lr": lr, "seed": seed}
        changes |= {"val_fraction": val_fraction, "precision": precision, "device": device}
        run = resolve_run(arch, config, changes, test_c, canvas_mm)
        _train(
            run,
            data,
            out,
            hand,
            init,
            resume,
            stop_after_epoch,
            cv_grid,
            cv_folds,
            progress,
            from_scratch,
        )
    except (HandskinError, KeyError) as err:
        raise fail(err) from err
    except OSError as err:  # a full disk while writing the run folder
        raise fail(ValueError(os_error_text(err))) from err


def _train(run, data, out, hand, init, resume, stop, cv_grid, cv_folds, progress, scratch) -> None:
    # optional: torch (the learn extra)
    from learn.data.load import load_data
    from learn.train import encoder
    from learn.train.checkpoint import versions
    from learn.train.crossval import cross_validate, cv_markdown, parse_grid
    from learn.train.device import check_precision
    from learn.train.loop import fit
    from learn.train.optim import check_init
    from learn.train.state import check_run_folder, check_stop
    from learn.train.validation import evaluate_tensors

    check_precision(run.device, run.precision)
    pretrain = encoder.wanted(scratch, run, data, init, cv_grid, out, resume)
    if init is not None:
        typer.echo(f"--init {init}: {check_init(run, init)[0].summary()}")
    if cv_grid and stop is not None:
        raise ConfigError(
            "--stop-after-epoch with --cv-grid: cross-validate first, then train the pick"
        )
    check_stop(stop, run, out, resume)
    check_run_folder(out, resume, data)
    if pretrain:  # every check passed: now the classifier, then its encoder as the start
        typer.echo(f"{run.model.arch}: first a vgg16 classifier in {out / encoder.FOLDER}")
        init = encoder.pretrain_encoder(run, data, out, progress)
        typer.echo(f"{run.model.arch} starts from {init}: {check_init(run, init)[0].summary()}")
    if cv_grid:
        cv = cross_validate(run, data, parse_grid(cv_grid), k=cv_folds, hand_classes=hand)
        out.mkdir(parents=True, exist_ok=True)
        write_text_atomic(out / "crossval.md", cv_markdown(cv) + "\n")
        typer.echo(cv_markdown(cv))
        run = cv.best_run
    loaded = load_data(data, run, hand_classes=hand, progress=progress)
    n = len(loaded.class_names)
    if run.task != "segment" and n != run.model.num_classes:  # a folder's classes, actions
        typer.echo(f"num_classes set to {n} ({', '.join(loaded.class_names)})")
        run = dataclasses.replace(run, model=dataclasses.replace(run.model, num_classes=n))
    result = fit(
        run, loaded, out, resume=resume, init=init, progress=progress, stop_after_epoch=stop
    )
    if result.paused:
        typer.echo(f"stopped after epoch {stop} of {run.train.epochs}; continue with --resume")
        return
    report = {"config": to_dict(run), "versions": versions(), "seed": run.train.seed}
    report |= {"data": loaded.description, "best_val_metric": result.best_metric}
    if loaded.test is not None:
        res = evaluate_tensors(result.model, loaded.test, run.model.num_classes)
        report |= {"test_metrics": res.metrics, "test_confusion": res.cm.tolist()}
        typer.echo("test: " + ", ".join(f"{k} {v:.4f}" for k, v in res.metrics.items()))
    write_text_atomic(out / "test_metrics.json", json.dumps(report, indent=1))
    typer.echo(f"run written to {out}")


def _train_classical(arch, data, out, config, seed, hand, init, epochs, progress, unused) -> None:
    """BoVW or VGG16 + SVM; ``unused``: the network options given (option -> value or None)."""
    from learn.classical.run import train_checked  # optional: torch (the learn extra)

    report = train_checked(
        arch,
        data,
        out,
        config_path=config,
        seed=seed,
        hand_classes=hand,
        init=init,
        epochs=epochs,
        unused=unused,
        progress=progress,
    )
    typer.echo("test: " + ", ".join(f"{k} {v:.4f}" for k, v in report["test_metrics"].items()))
    typer.echo(f"model written to {out / 'model.npz'}")


def evaluate_command(
    data: DataArg,
    checkpoints: Annotated[
        list[Path],
        typer.Argument(metavar="CHECKPOINT", help="Checkpoints (.pt) or baselines (model.npz)."),
    ],
    out: opt(Path, "The markdown report (.md); its rows as .json beside it.") = Path("report.md"),
    threads: ThreadsOpt = 1,
    hand_names: HandOpt = None,
    tta: TtaOpt = False,
    ensemble: opt(
        bool, "Also score each task's networks together (their mean softmax).", "--ensemble"
    ) = False,
    int8: opt(
        bool, "Also score each HandsNet as int8 (calibrated on DATASET's train split).", "--int8"
    ) = False,
    time_runs: opt(int, "Timed batch-1 runs per inference path and round (count).") = 100,
    time_rounds: opt(int, "Rounds in which a network's inference paths take turns (count).") = 3,
    progress: ProgressOpt = True,
) -> None:
    """Score checkpoints on DATASET's test split beside the paper's Tables 3 and 8."""
    # optional: torch (the learn extra)
    from learn.classical.run import evaluate_classical
    from learn.classical.svm import load_npz
    from learn.evaluate.report import write_report
    from learn.evaluate.scoring import eval_jobs, evaluate_job
    from learn.infer.fastpath import check_timing
    from learn.train.checkpoint import versions

    hand = hand_classes(hand_names)
    timing = {"threads": threads, "time_runs": time_runs, "time_rounds": time_rounds}
    try:
        check_timing(time_runs, time_rounds, threads)
        _check_data(data)
        require_folder(out.parent, "--out", "give a file path in a folder")
        require_writable(out, "--out")
        models = [c for c in checkpoints if c.suffix == ".npz"]
        for m in models:
            load_npz(m)
        jobs = eval_jobs([c for c in checkpoints if c.suffix != ".npz"], tta, ensemble, int8)
        rows = [evaluate_job(j, data, hand_classes=hand, **timing) for j in jobs]
        rows += [evaluate_classical(m, data, hand_classes=hand, **timing) for m in models]
    except (HandskinError, KeyError) as err:
        raise fail(err) from err
    flags = [f for f, on in (("--tta", tta), ("--ensemble", ensemble), ("--int8", int8)) if on]
    words = ["handskin", "evaluate", str(data), *map(str, checkpoints), "--out", str(out), *flags]
    words += ["--threads", str(threads), "--time-runs", str(time_runs)]
    words += ["--time-rounds", str(time_rounds)] + (["--hand-classes", hand_names] if hand else [])
    header = f"Regenerate: `{shlex.join(words)}`\n\nVersions: {json.dumps(versions())}."
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        write_report(rows, out, header)
    except OSError as err:
        raise fail(ValueError(os_error_text(err))) from err
    typer.echo(f"report written to {out}")


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
        for flag, path in (("--out", out), ("--png", png)):
            if path is not None:
                require_writable(path, flag)
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
            frame = to_pa(P.read_frame(source, layout))
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
    """Recognise a stream of frames: one JSON answer per frame (docs/learning.md, Stream)."""
    from learn.infer import serve as S  # optional: torch (the learn extra)

    try:
        for path in [*(classifier or ()), *(segmenter or ())]:
            if not path.is_file():
                raise DataError(
                    f"no checkpoint at {path}. Fix: give a .pt file from handskin train"
                )
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


def quantize_command(
    checkpoint: Annotated[
        Path,
        typer.Argument(metavar="CHECKPOINT", help="HandsNet checkpoint (.pt from handskin train)."),
    ],
    out: opt(
        Path | None, "The int8 file (.pt; default <stem>_int8.pt beside the checkpoint)."
    ) = None,
    calibration: opt(
        Path | None, "Data whose train split sets the 8-bit ranges (default: its own)."
    ) = None,
    images: opt(
        int, "Calibration images drawn from that train split by the run's seed (count)."
    ) = 512,
) -> None:
    """HandsNet as an int8 file: calibrated once, run as int8 by predict and evaluate."""
    # optional: torch (the learn extra)
    import torch

    from learn.infer import int8_file as F
    from learn.infer.fastpath import cpu_ms_per_image
    from learn.infer.quantize import MIN_CALIBRATION, int8_supported, quantize_int8, traceable_body
    from learn.models import prepare_for_inference
    from learn.train.checkpoint import (
        is_int8,
        load_checkpoint,
        model_from_checkpoint,
        save_checkpoint,
    )

    try:
        out = out or checkpoint.with_name(f"{checkpoint.stem}_int8.pt")
        ckpt = load_checkpoint(checkpoint)
        model, run = model_from_checkpoint(ckpt, where=checkpoint)  # refuses an int8 file
        traceable_body(model)
        if not int8_supported():
            raise ConfigError(
                "this PyTorch has no oneDNN quantized engine. Fix: run HandsNet in float"
            )
        if images < MIN_CALIBRATION:
            raise ConfigError(f"--images {images}: calibrate on at least {MIN_CALIBRATION} images")
        if out.resolve() == checkpoint.resolve():
            raise ConfigError(f"--out {out} is the checkpoint itself. Fix: another file name")
        if out.suffix != ".pt":
            raise ConfigError(f"--out {out}: name the int8 file with a .pt suffix")
        if out.exists() and not is_int8(load_checkpoint(out)):
            raise ConfigError(f"--out {out} holds a float checkpoint; it is not written over")
        require_writable(out, "--out")
        where = F.calibration_source(ckpt, calibration)
        hand = (ckpt.get("data") or {}).get("hand_classes")
        calib = F.calibration_images(where, run, hand and tuple(hand), images)
        net = quantize_int8(model, calib)
    except (HandskinError, KeyError) as err:
        raise fail(err) from err
    with torch.no_grad():
        agree = float((model(calib).argmax(1) == net(calib).argmax(1)).float().mean())
    try:
        save_checkpoint(F.int8_checkpoint(ckpt, net, where, len(calib), checkpoint), out)
    except HandskinError as err:  # a full disk: no temporary file is left
        raise fail(err) from err
    size = run.model.input_size
    ms_float = cpu_ms_per_image(prepare_for_inference(model), size, 1, 50)
    ms_int8 = cpu_ms_per_image(net, size, 1, 50)
    typer.echo(
        f"int8 HandsNet written to {out}: ranges from {len(calib)} train images of {where}; "
        f"same class as the float network on {100 * agree:.2f} % of them; {ms_int8:.2f} "
        f"ms/image against {ms_float:.2f} in float (CPU, 1 thread, batch 1)"
    )


def register(app: typer.Typer) -> None:
    """Add `train`, `evaluate`, `predict`, `stream` and `quantize` to the `handskin` app."""
    for name, command in (
        ("train", train_command),
        ("evaluate", evaluate_command),
        ("predict", predict_command),
        ("stream", stream_command),
        ("quantize", quantize_command),
    ):
        app.command(name)(needs_torch(command))
