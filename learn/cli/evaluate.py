"""`handskin evaluate` (checkpoints scored beside the paper's tables) and `handskin quantize`
(HandsNet as int8)."""

from __future__ import annotations

import json
import shlex
from pathlib import Path
from typing import Annotated

import typer

from learn.cli.options import (
    DataArg,
    HandOpt,
    ProgressOpt,
    ThreadsOpt,
    TtaOpt,
    check_data,
    fail,
    hand_classes,
    is_dataset_path,
    opt,
)
from tactile.dataset.boxes import is_box_folder
from tactile.errors import ConfigError, HandskinError, require_folder
from tactile.files import os_error_text, require_output


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
    negatives: opt(
        Path | None,
        "Real box folders: the simulated dataset whose test non-hands a classifier is scored on "
        "(default: the dataset it was trained on).",
    ) = None,
    time_runs: opt(int, "Timed batch-1 runs per inference path and round (count).") = 100,
    time_rounds: opt(int, "Rounds in which a network's inference paths take turns (count).") = 3,
    progress: ProgressOpt = True,
) -> None:
    """Score checkpoints on DATASET's test split beside the paper's Tables 3 and 8.

    Given a folder of real box-labelled prints (handskin ingest-boxes), score them there
    instead: a classifier's hand recall beside its specificity on simulated non-hands, a
    segmenter's part localisation in the real boxes and their IoU, and a picture (<out>.png)."""
    # optional: torch (the learn extra)
    from learn.classical.run import evaluate_classical
    from learn.classical.svm import load_npz
    from learn.evaluate.report import write_report
    from learn.evaluate.scoring import eval_jobs, evaluate_job, report_rows
    from learn.infer.fastpath import check_timing
    from learn.train.checkpoint import versions

    if is_box_folder(data):
        return real_command(data, checkpoints, out, negatives)
    hand = hand_classes(hand_names)
    timing = {"threads": threads, "time_runs": time_runs, "time_rounds": time_rounds}
    try:
        check_timing(time_runs, time_rounds, threads)
        check_data(data)
        if hand and is_dataset_path(data):
            raise ConfigError(
                f"--hand-classes {hand_names}: names the hand folders of an image folder, but "
                f"{data} is a handskin dataset, whose samples say hand or not. Fix: drop it"
            )
        require_folder(out.parent, "--out", "give a file path in a folder")
        beside = [out.with_suffix(".json"), out.with_name(f"{out.stem}_actions_frames.png")]
        beside += [out.with_name(f"{out.stem}_actions_confusion.png")]
        require_output(out, "--out", reads=[data, *checkpoints], suffixes=(".md",), derived=beside)
        models = [c for c in checkpoints if c.suffix == ".npz"]
        for m in models:
            load_npz(m)
        jobs = eval_jobs([c for c in checkpoints if c.suffix != ".npz"], tta, ensemble, int8)
        rows = []
        for j in jobs:
            rows += report_rows(
                evaluate_job(j, data, hand_classes=hand, **timing, progress=progress)
            )
        rows += [
            evaluate_classical(m, data, hand_classes=hand, **timing, progress=progress)
            for m in models
        ]
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


def real_command(data: Path, checkpoints: list[Path], out: Path, negatives: Path | None) -> None:
    """`handskin evaluate` on a folder of real box-labelled prints (`learn.evaluate.real`)."""
    from learn.classical.run import real_hand_scores  # torch
    from learn.evaluate.real import evaluate_real, real_picture, write_real_report

    try:
        require_folder(out.parent, "--out", "give a file path in a folder")
        beside = [out.with_suffix(".json"), out.with_suffix(".png")]
        reads = [data, *checkpoints, negatives]
        require_output(out, "--out", reads=reads, suffixes=(".md",), derived=beside)
        if negatives is not None:
            check_data(negatives)
        rows, predictions = [], None
        for path in checkpoints:  # in the order given; the picture shows the last segmenter's
            if path.suffix == ".npz":
                rows.append(real_hand_scores(path, data, negatives))
                continue
            (row,), seen = evaluate_real(data, [path], negatives)
            rows.append(row)
            predictions = seen if seen is not None else predictions
    except (HandskinError, KeyError) as err:
        raise fail(err) from err
    words = ["handskin", "evaluate", str(data), *map(str, checkpoints), "--out", str(out)]
    words += ["--negatives", str(negatives)] if negatives is not None else []
    header = f"Regenerate: `{shlex.join(words)}`\n\nReal prints: `{data}`; part labels box-derived."
    try:
        write_real_report(rows, out, header)
        if predictions is not None:
            real_picture(data, predictions, out.with_suffix(".png"))
    except OSError as err:
        raise fail(ValueError(os_error_text(err))) from err
    typer.echo(f"report written to {out}")


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
        require_output(out, "--out", reads=[checkpoint, calibration], suffixes=(".pt",))
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
