"""`handskin train`, `handskin evaluate`, `handskin predict` (``register(app)`` adds them).

Every input is checked (files exist, configuration valid, architecture known) before any work;
errors print ``error: <what and how to fix>`` and exit with status 2.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib.util
import json
from pathlib import Path
from typing import Annotated

import typer

from tactile.errors import ConfigError, DataError, HandskinError, require_folder

PRESETS = ("handsnet", "vgg16", "segnet", "fcn16s")
CLASSICAL = ("bovw", "vgg_svm")  # as learn.classical.CLASSICAL (not imported: keeps --help fast)


def _fail(err: Exception) -> typer.Exit:
    typer.echo(f"error: {err.args[0] if isinstance(err, KeyError) else err}", err=True)
    return typer.Exit(2)


def _hand_classes(text: str | None) -> tuple[str, ...] | None:
    return None if not text else tuple(t.strip() for t in text.split(",") if t.strip())


# overrides of RunConfig itself, not of its train table
RUN_KEYS = ("val_fraction", "precision", "device", "distill_from")


def resolve_run(arch: str, config: Path | None, overrides: dict, test_c: bool):
    """The RunConfig: the arch's preset, the TOML file over it, then command-line overrides."""
    from learn import config as C
    from learn.train import RunConfig, load_run_config, replace_train

    if arch not in PRESETS:
        raise ConfigError(f"unknown arch {arch!r}; choose one of: {', '.join(PRESETS + CLASSICAL)}")
    preset = C.PRESET_OF_ARCH[arch]
    run = RunConfig(model=preset.model, train=C.FINETUNE_TEST_C if test_c else preset.train)
    run = load_run_config(config, run) if config is not None else run
    top = {k: overrides[k] for k in RUN_KEYS if overrides.get(k) is not None}
    train = {k: v for k, v in overrides.items() if v is not None and k not in RUN_KEYS}
    run = replace_train(run, **train) if train else run
    return dataclasses.replace(run, **top) if top else run


def parse_canvas(text: str) -> tuple[float, float]:
    """'H,W' (mm) -> (H, W); ConfigError naming the fix when malformed or not positive."""
    try:
        h, w = (float(t) for t in text.split(","))
    except ValueError:
        h = w = float("nan")
    if not (h > 0 and w > 0):
        raise ConfigError(
            f"--canvas-mm {text!r}: give the canvas as H,W in mm, both > 0, e.g. "
            "229,383 (the forearm map)"
        )
    return h, w


def _check_data(data: Path) -> None:
    from learn.folder import is_dataset

    if not (is_dataset(data) or data.is_dir()):
        raise DataError(
            f"no dataset or image folder at {data}. Fix: give a dataset folder "
            "(holding dataset.h5) or a folder of class sub-folders of images"
        )


def _refuse_repeats(checkpoints: list[Path]) -> None:
    """A ConfigError when one file is given twice (its rows would be scored twice)."""
    seen: set[Path] = set()
    for c in checkpoints:
        if c.resolve() in seen:
            raise ConfigError(f"{c} is given twice. Fix: give each checkpoint or model file once")
        seen.add(c.resolve())


def _fit_classes(run, data):
    """Classification on a folder keeping every class: num_classes follows the folders."""
    n = len(data.class_names)
    if run.task == "classify" and n != run.model.num_classes:
        typer.echo(f"num_classes set to {n} ({', '.join(data.class_names)})")
        run = dataclasses.replace(run, model=dataclasses.replace(run.model, num_classes=n))
    return run


def _opt(kind, help_text: str, *names: str):
    """``Annotated[kind, typer.Option(*names, help=help_text)]``."""
    return Annotated[kind, typer.Option(*names, help=help_text)]


DataArg = Annotated[Path, typer.Argument(help="Dataset folder (dataset.h5) or image folder.")]
OutOpt = _opt(Path, "Run folder: checkpoints, curves.png, run.toml.")
ArchOpt = _opt(
    str,
    "handsnet | vgg16 | segnet | fcn16s (its preset configuration), or the "
    "classical baselines of Table 3: bovw | vgg_svm (OUT/model.npz; no unit).",
)
ConfigOpt = _opt(
    Path | None,
    "TOML run config: model and train tables and top-level "
    "RunConfig keys, laid over the arch's preset (bovw / vgg_svm: top-level "
    "BovwConfig / VggSvmConfig keys; bovw also input_size = [h, w] px).",
)
EpochsOpt = _opt(
    int | None,
    "Epochs (each a pass over every train image in every view: 3 "
    "with flips); vgg_svm without --init: epochs of the vgg16 trained first into "
    "OUT/vgg16.",
)
BatchOpt = _opt(int | None, "Images per optimisation step.")
LrOpt = _opt(float | None, "Initial learning rate (dimensionless, per step).")
SeedOpt = _opt(int | None, "Seed of init, shuffling and splits (integer).")
ValOpt = _opt(float | None, "Share (0-1) of the train split's subjects held out for validation.")
PrecisionOpt = _opt(
    str | None,
    "Number format of the training forward pass: fp32 (the preset) "
    "or bf16 (bfloat16 autocast, weights and loss in fp32; about 1.8x faster "
    "steps on CPUs with native bf16: AVX512-BF16 or AMX; no unit).",
)
DeviceOpt = _opt(
    str | None,
    "Where the model trains: cpu (the default; the same seed gives the "
    "same weights) or cuda / cuda:N (a GPU, with a CUDA build of torch; for the "
    "full-width networks, e.g. width = 1.0 in a run TOML); no unit.",
)
HandOpt = _opt(
    str | None,
    "Image folders: comma-separated folder names that are 'hand' "
    "(e.g. hand,finger); default: every folder its own class.",
)
InitOpt = _opt(
    Path | None,
    "Fine-tune from this checkpoint (.pt file): the tensors whose names "
    "and shapes fit load, the rest start fresh; segnet / fcn16s: a vgg16 classifier "
    "of the same width lends its encoder (+2.5 to +7.9 mIoU points on the paper-sized "
    "set, docs/learning.md); vgg_svm: the vgg16 checkpoint whose features feed the SVM.",
)
DistillOpt = _opt(
    Path | None,
    "Distil from this trained classifier (.pt file, e.g. a vgg16 "
    "best.pt of the same data): the network also learns its flip-averaged "
    "probabilities (distill_weight, dimensionless share of the loss, and "
    "distill_temperature, dimensionless, in a run TOML).",
)
TestCOpt = _opt(
    bool,
    "The paper's Test C schedule: lr 0.01 halved at epoch 60 of 120, batch 128 "
    "images, lr x 0.1 on the first two convolutions.",
)
CanvasOpt = _opt(
    str | None,
    "Input canvas 'H,W' in mm (e.g. 229,383, the forearm map): each "
    "map centred on it (zero-padded or cropped) before the resize, so a mm is the "
    "same number of input pixels on any part. Default: stretch each map (paper).",
)
ResumeOpt = _opt(bool, "Continue from OUT/last.pt.")
StopOpt = _opt(
    int | None,
    "Stop once this epoch (1-based, counted from the run's start) is "
    "done, keeping the schedule of all the epochs, to split a long run; no test "
    "scores until --resume finishes it (epoch number, no unit).",
)
GridOpt = _opt(
    str | None,
    "Cross-validate first over a grid, e.g. "
    "'train.lr=0.01,0.001;train.batch_size=32,64' (each value in its field's unit).",
)
FoldsOpt = _opt(int, "Folds of the cross-validation (count).")
PretrainOpt = _opt(
    bool | None,
    "segnet / fcn16s on a handskin dataset: first train a vgg16 "
    "hand / non-hand classifier of the same width and seed on the same training "
    "images into OUT/vgg16 (20 epochs, lr x 0.2 after 14; 6.2 min on 2 cores for "
    "the paper-sized set; reused when there) and start from its encoder, as the "
    "paper's segmenters start from a pretrained VGG16. Default: on for a "
    "segmenter on a handskin dataset without --init or --cv-grid; "
    "--no-pretrain-encoder trains from scratch.",
    "--pretrain-encoder/--no-pretrain-encoder",
)
ProgressOpt = _opt(bool, "Show progress bars.")


def train_command(
    data: DataArg,
    out: OutOpt,
    arch: ArchOpt = "handsnet",
    config: ConfigOpt = None,
    epochs: EpochsOpt = None,
    batch_size: BatchOpt = None,
    lr: LrOpt = None,
    seed: SeedOpt = None,
    val_fraction: ValOpt = None,
    precision: PrecisionOpt = None,
    device: DeviceOpt = None,
    hand_classes: HandOpt = None,
    init: InitOpt = None,
    distill_from: DistillOpt = None,
    test_c: TestCOpt = False,
    canvas_mm: CanvasOpt = None,
    resume: ResumeOpt = False,
    stop_after_epoch: StopOpt = None,
    cv_grid: GridOpt = None,
    cv_folds: FoldsOpt = 5,
    pretrain_encoder: PretrainOpt = None,
    progress: ProgressOpt = True,
) -> None:
    """Train a model; best.pt / last.pt, curves.png, run.toml and test_metrics.json in OUT."""
    try:
        _check_data(data)
        require_folder(out)
        if init is not None and not init.is_file():
            raise DataError(f"no checkpoint at {init}. Fix: give a .pt file from handskin train")
        if arch in CLASSICAL:
            unused = {
                "--batch-size": batch_size,
                "--lr": lr,
                "--val-fraction": val_fraction,
                "--precision": precision,
                "--device": device,
                "--test-c": test_c or None,
                "--distill-from": distill_from,
                "--resume": resume or None,
                "--cv-grid": cv_grid,
                "--stop-after-epoch": stop_after_epoch,
                "--canvas-mm": canvas_mm,
                "--pretrain-encoder": pretrain_encoder or None,
            }
            _train_classical(
                arch,
                data,
                out,
                config,
                seed,
                _hand_classes(hand_classes),
                init,
                epochs,
                unused,
                progress,
            )
            return
        over = {
            "epochs": epochs,
            "batch_size": batch_size,
            "lr": lr,
            "seed": seed,
            "val_fraction": val_fraction,
            "precision": precision,
            "device": device,
            "distill_from": None if distill_from is None else str(distill_from),
        }
        run = resolve_run(arch, config, over, test_c)
        if canvas_mm is not None:
            model = dataclasses.replace(run.model, canvas_mm=parse_canvas(canvas_mm))
            run = dataclasses.replace(run, model=model)
        _train(
            run,
            data,
            out,
            _hand_classes(hand_classes),
            init,
            resume,
            stop_after_epoch,
            cv_grid,
            cv_folds,
            progress,
            pretrain_encoder,
        )
    except (HandskinError, KeyError) as err:
        raise _fail(err) from err


def _train(
    run,
    data,
    out,
    hand,
    init,
    resume,
    stop,
    cv_grid,
    cv_folds,
    progress,
    pretrain: bool | None = None,
) -> None:
    from learn.checkpoint import check_no_overwrite, versions
    from learn.crossval import cross_validate, cv_markdown, parse_grid
    from learn.evaluate import evaluate_tensors
    from learn.finetune import check_init
    from learn.leakage import own_split_note, test_hands
    from learn.run_state import check_stop
    from learn.train import check_precision, fit, load_data
    from tactile.config import to_dict

    check_precision(run)
    teacher = None
    if run.distill_from:
        from learn.distill import check_teacher

        if cv_grid:
            raise ConfigError(
                "--distill-from with --cv-grid: the teacher trained on every fold's "
                "validation people, so the folds would not be held out. Fix: "
                "cross-validate without the teacher, then distil the pick"
            )
        teacher = check_teacher(run, data)
    from learn.encoder_start import check_pretrain, wanted

    pretrain = wanted(pretrain, run, data, init, cv_grid, out, resume)
    if pretrain:
        check_pretrain(run, data, init, cv_grid)
    init_ckpt = None
    if init is not None:
        loads, init_ckpt = check_init(run, init, data)
        typer.echo(f"--init {init}: {loads.summary()}")
    if cv_grid and stop is not None:
        raise ConfigError(
            "--stop-after-epoch with --cv-grid: the grid's pick would be lost on "
            "--resume. Fix: cross-validate first, then train the pick in parts"
        )
    check_stop(stop, run, out, resume)
    check_no_overwrite(out, resume)
    if note := own_split_note(data, test_hands(data) if run.task == "segment" else None):
        typer.echo(f"warning: {note}", err=True)
    if pretrain:  # the checks above passed: now the classifier, then its encoder as the start
        from learn.encoder_start import FOLDER, pretrain_encoder

        typer.echo(
            f"{run.model.arch}: first a vgg16 classifier in {out / FOLDER}, whose encoder "
            "starts it (--no-pretrain-encoder: from scratch)"
        )
        init = pretrain_encoder(run, data, out, progress)
        loads, init_ckpt = check_init(run, init, data)
        typer.echo(f"{run.model.arch} starts from the encoder of {init}: {loads.summary()}")
    grid = parse_grid(cv_grid) if cv_grid else None
    if grid:
        cv = cross_validate(run, data, grid, k=cv_folds, hand_classes=hand)
        out.mkdir(parents=True, exist_ok=True)
        (out / "crossval.md").write_text(cv_markdown(cv) + "\n")
        typer.echo(cv_markdown(cv))
        run = cv.best_run
    loaded = load_data(data, run, hand_classes=hand, progress=progress)
    fitted = _fit_classes(run, loaded)
    teacher = teacher if fitted is run else None  # classes changed: fit checks the teacher again
    run = fitted
    result = fit(
        run,
        loaded,
        out,
        resume=resume,
        init_from=init,
        progress=progress,
        stop_after_epoch=stop,
        teacher=teacher,
        init_checkpoint=init_ckpt,
    )
    if result.paused:
        typer.echo(
            f"stopped after epoch {stop} of {run.train.epochs} (run in {out}); continue "
            "with the same command and --resume, without --stop-after-epoch to finish"
        )
        return
    report = {
        "config": to_dict(run),
        "versions": versions(),
        "seed": run.train.seed,
        "data": loaded.description,
        "best_val_metric": result.best_metric,
    }
    if loaded.test is not None:
        res = evaluate_tensors(result.model, loaded.test, run.model.num_classes)
        report |= {"test_metrics": res.metrics, "test_confusion": res.cm.tolist()}
        typer.echo("test: " + ", ".join(f"{k} {v:.4f}" for k, v in res.metrics.items()))
    (out / "test_metrics.json").write_text(json.dumps(report, indent=1))
    typer.echo(f"run written to {out}")


def _train_classical(arch, data, out, config, seed, hand, init, epochs, unused, progress) -> None:
    """BoVW or VGG16 + SVM (``learn.classical.train_checked``): OUT/model.npz and metrics."""
    from learn.classical import MODEL_FILE, train_checked

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
    typer.echo(f"model written to {out / MODEL_FILE}")


CkptsArg = Annotated[
    list[Path],
    typer.Argument(
        help="Checkpoints (.pt files) or classical models (model.npz from --arch bovw / vgg_svm)."
    ),
]
EvalDataOpt = _opt(Path, "Dataset folder or image folder (its test split is used).")
ReportOpt = _opt(
    Path,
    "Markdown report to write (.md file; a .json beside it, and on a handskin "
    "dataset a PNG per network of where it fails: <stem>_errors_<model>.png).",
)
ThreadsOpt = _opt(int, "CPU threads used for the timing (count).")
EvalHandOpt = _opt(str | None, "Image folders: hand folder names (default: the checkpoint's).")
EvalTtaOpt = _opt(
    bool,
    "Also score each network (.pt) with test-time flips, in a row of its "
    "own: the mean softmax over the views it was trained on (original, columns "
    "and rows reversed), about 3x the ms per image.",
    "--tta",
)
EnsembleOpt = _opt(
    bool,
    "Also score the mean softmax of all the networks (.pt) given for each "
    "task with two or more, in a row of its own (and, with --tta, with flips); "
    "its ms per image is about the sum of its members'.",
    "--ensemble",
)
Int8Opt = _opt(
    bool,
    "Also score each HandsNet (.pt) as an int8 network (oneDNN, activation "
    "ranges from 512 training images of --data), in a row of its own; on AVX2 CPUs "
    "about 1.5x faster per image than the float fast path.",
    "--int8",
)
CompileOpt = _opt(
    bool,
    "Also time each network's float fast path compiled by TorchInductor "
    "(torch.compile, weights frozen; needs a C++ compiler): ms per image at batch "
    "1, shown in the tables when faster. Costs 5-20 s of compiling per row.",
    "--compile",
)
TimeRunsOpt = _opt(
    int,
    "Timed batch-1 runs per inference path and round, after 10 warm-up runs "
    "(count); each path's time is the median of a round.",
)
TimeRoundsOpt = _opt(
    int,
    "Rounds of timing in which a network's inference paths (eval mode, "
    "prepared, fast, compiled) take turns; the least median is kept (count).",
)


def evaluate_command(
    checkpoints: CkptsArg,
    data: EvalDataOpt,
    report: ReportOpt = Path("report.md"),
    threads: ThreadsOpt = 1,
    hand_classes: EvalHandOpt = None,
    tta: EvalTtaOpt = False,
    ensemble: EnsembleOpt = False,
    int8: Int8Opt = False,
    compiled: CompileOpt = False,
    time_runs: TimeRunsOpt = 100,
    time_rounds: TimeRoundsOpt = 3,
) -> None:
    """Metrics, confusion matrices (% of true class) and CPU ms/image next to the paper."""
    from learn.checkpoint import versions
    from learn.error_sheets import save_error_sheets
    from learn.eval_jobs import eval_jobs
    from learn.eval_report import report_json, write_report
    from learn.evaluate import evaluate_checkpoint, evaluate_ensemble
    from learn.fastpath import check_timing

    try:
        check_timing(time_runs, time_rounds, threads)
        _check_data(data)
        _refuse_repeats(checkpoints)
        jobs = eval_jobs(checkpoints, tta, ensemble, int8)
        hand = _hand_classes(hand_classes)
        timing = {"threads": threads, "time_runs": time_runs}
        rows = [
            evaluate_ensemble(
                c,
                data,
                hand_classes=hand,
                tta=t,
                compiled=compiled,
                time_rounds=time_rounds,
                **timing,
            )
            if isinstance(c, list)
            else evaluate_checkpoint(
                c,
                data,
                hand_classes=hand,
                tta=t,
                int8=q,
                compiled=compiled,
                time_rounds=time_rounds,
                **timing,
            )
            for c, t, q in jobs
        ]
    except (HandskinError, KeyError) as err:
        raise _fail(err) from err
    from learn.leakage import leakage_note

    for row in rows:
        if note := leakage_note(row.get("shared_with_training")):
            typer.echo(f"warning: {row['checkpoint']}: {note.replace('**', '')}", err=True)
        if note := row.get("compile_note"):
            typer.echo(f"warning: {row['checkpoint']}: not timed compiled: {note}", err=True)
    header = f"Data: `{data}`. Versions: {json.dumps(versions())}."
    for path in save_error_sheets(rows, data, report):
        typer.echo(f"picture written to {path}")
    write_report(rows, report, header)
    report.with_suffix(".json").write_text(report_json(rows))
    typer.echo(f"report written to {report}")


def _needs_torch(command):
    """``command`` preceded by a clear error when PyTorch is not installed (it is an extra)."""

    @functools.wraps(command)
    def checked(*args, **kwargs):
        if importlib.util.find_spec("torch") is None:
            typer.echo(
                "error: this command needs PyTorch, which handskin installs only with its 'learn' "
                "extra. Fix: pip install 'handskin[learn]' (on a machine without a GPU, install "
                "the CPU wheel of torch first)",
                err=True,
            )
            raise typer.Exit(2)
        return command(*args, **kwargs)

    return checked


def register(app: typer.Typer) -> None:
    """Add `train`, `evaluate`, `predict` and `quantize` to the `handskin` app."""
    app.command("train")(_needs_torch(train_command))
    app.command("evaluate")(_needs_torch(evaluate_command))
    from learn.predict_cli import predict_command
    from learn.quantize_cli import quantize_command

    app.command("predict")(_needs_torch(predict_command))
    app.command("quantize")(_needs_torch(quantize_command))
