"""`handskin train`: a network or a classical baseline on a dataset's train split."""

from __future__ import annotations

import dataclasses
import json
import warnings
from pathlib import Path

import typer

from learn import config as C
from learn.cli.options import (
    DataArg,
    DeviceOpt,
    HandOpt,
    ProgressOpt,
    SeedOpt,
    check_data,
    fail,
    hand_classes,
    is_dataset_path,
    opt,
)
from tactile.config import read_toml, to_dict
from tactile.dataset.boxes import is_box_folder
from tactile.dataset.reader import open_dataset
from tactile.errors import ConfigError, HandskinError, require_folder
from tactile.files import os_error_text, require_output, write_text_atomic

CLASSICAL = ("bovw", "vgg_svm")  # as learn.classical.svm.CLASSICAL (not imported: fast --help)
MAX_SEED = 2**63 - 1  # torch's seeds are 64-bit signed integers


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


def check_numbers(seed: int | None, folds: int) -> None:
    """ConfigError naming the flag of a number out of its range, before any work
    (--stop-after-epoch: `learn.train.state.check_stop`, against the run's epochs)."""
    if seed is not None and not 0 <= seed <= MAX_SEED:
        raise ConfigError(f"--seed {seed} is out of range; allowed [0, {MAX_SEED}]")
    if folds < 2:
        raise ConfigError(f"--cv-folds {folds} is out of range; allowed >= 2 (each held out once)")


def choose_arch(arch: str | None, config: Path | None) -> str:
    """``--arch``, else the ``--config`` TOML's ``[model] arch``, else handsnet; ConfigError when
    both are given and differ (one would silently override the other)."""
    model = read_toml(config).get("model") if config is not None else None
    in_toml = model.get("arch") if isinstance(model, dict) else None
    if arch is not None and in_toml is not None and arch != in_toml:
        raise ConfigError(
            f"--arch {arch} against [model] arch = {in_toml!r} in {config}: which one should "
            f"train? Fix: drop --arch (then {in_toml} trains) or change the TOML's arch"
        )
    return arch or in_toml or "handsnet"


def warn_crop(canvas_mm: tuple[float, float], data: Path) -> None:
    """A warning when the model's canvas keeps less than half of DATASET's map: most prints
    would be cut away (centred on a canvas smaller than the map)."""
    with open_dataset(data) as ds:
        h_mm, w_mm = (n * ds.map.step_mm for n in ds.map.shape)
    kept = min(canvas_mm[0], h_mm) * min(canvas_mm[1], w_mm) / (h_mm * w_mm)
    if kept < 0.5:
        warnings.warn(
            f"the canvas of {canvas_mm[0]:g} x {canvas_mm[1]:g} mm (--canvas-mm or "
            f"model.canvas_mm) keeps {100 * kept:.1f} % of the {h_mm:.0f} x {w_mm:.0f} mm map "
            f"of {data}: the rest of each print is cut away. Fix: a canvas as large as the "
            f"map, e.g. --canvas-mm {h_mm:.0f},{w_mm:.0f}",
            stacklevel=2,
        )


def train_command(
    data: DataArg,
    out: opt(Path, "Run folder: best.pt, last.pt, curves.png, run.toml, test_metrics.json."),
    arch: opt(
        str | None,
        "handsnet | vgg16 | segnet | fcn16s | action_3d, or bovw | vgg_svm (default: the "
        "--config's [model] arch, else handsnet).",
    ) = None,
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
        check_data(data)
        require_folder(out)
        require_output(out, "--out", reads=[data, config, init], folder=True, makes="run")
        check_numbers(seed, cv_folds)
        if hand and is_dataset_path(data):
            raise ConfigError(
                f"--hand-classes {hand_names}: names the hand folders of an image folder, but "
                f"{data} is a handskin dataset, whose samples say hand or not. Fix: drop it"
            )
        arch = choose_arch(arch, config)
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
        if run.model.canvas_mm is not None and is_dataset_path(data):
            warn_crop(run.model.canvas_mm, data)
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
        if run.task == "segment" and is_box_folder(data):
            typer.echo(
                f"{data} holds real box-labelled prints: handskin finetune trains a segmenter "
                "on them by the recipe measured on real prints (docs/learning.md)"
            )
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
