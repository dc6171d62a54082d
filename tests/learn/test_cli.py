"""`handskin train / evaluate / predict` through typer's CliRunner on a local app."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import typer
from typer.testing import CliRunner

from learn.checkpoint import load_checkpoint
from learn.cli import register
from tactile.dataset import open_dataset

runner = CliRunner()


@pytest.fixture(scope="module")
def app() -> typer.Typer:
    app = typer.Typer()
    register(app)
    return app


@pytest.fixture
def small_config(tmp_path):
    path = tmp_path / "run.toml"
    path.write_text(
        "threads = 1\n[model]\ninput_size = [32, 48]\n[train]\nepochs = 2\nbatch_size = 16\n"
    )
    return path


def test_train_evaluate_predict(app, tiny_dataset, small_config, checkpoints, tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(
        app,
        [
            "train",
            str(tiny_dataset),
            "--out",
            str(out),
            "--config",
            str(small_config),
            "--no-progress",
            "--seed",
            "1",
        ],
    )
    assert res.exit_code == 0, res.output
    for name in ("best.pt", "last.pt", "curves.png", "run.toml", "test_metrics.json"):
        assert (out / name).is_file(), name
    report = json.loads((out / "test_metrics.json").read_text())
    assert report["seed"] == 1 and "torch" in report["versions"]
    assert "accuracy" in report["test_metrics"]
    md = tmp_path / "report.md"
    res = runner.invoke(
        app,
        [
            "evaluate",
            str(out / "best.pt"),
            str(checkpoints["segnet"]),
            "--data",
            str(tiny_dataset),
            "--report",
            str(md),
        ],
    )
    assert res.exit_code == 0, res.output
    assert "Table 3" in md.read_text() and md.with_suffix(".json").is_file()
    frame = tmp_path / "frame.npy"
    np.save(frame, open_dataset(tiny_dataset).raw[2])
    res = runner.invoke(
        app,
        [
            "predict",
            "--frame",
            str(frame),
            "--map",
            str(tiny_dataset),
            "--classifier",
            str(out / "best.pt"),
            "--segmenter",
            str(checkpoints["segnet"]),
            "--png",
            str(tmp_path / "p.png"),
        ],
    )
    assert res.exit_code == 0, res.output
    assert "probability" in res.output and "palm" in res.output and (tmp_path / "p.png").is_file()


def test_train_in_parts_equals_one_run(app, tiny_dataset, small_config, tmp_path):
    """--stop-after-epoch then --resume gives the uninterrupted run's epochs and test scores;
    the paused run writes no test scores; a stop the resumed run has passed, and a fresh start
    over the paused run, are refused."""
    base = ["train", str(tiny_dataset), "--config", str(small_config), "--no-progress"]
    whole, parts = tmp_path / "whole", tmp_path / "parts"
    assert runner.invoke(app, [*base, "--out", str(whole)]).exit_code == 0
    res = runner.invoke(app, [*base, "--out", str(parts), "--stop-after-epoch", "1"])
    assert res.exit_code == 0 and "stopped after epoch 1 of 2" in res.output, res.output
    assert (parts / "last.pt").is_file() and not (parts / "test_metrics.json").exists()
    res = runner.invoke(app, [*base, "--out", str(parts), "--resume", "--stop-after-epoch", "1"])
    assert res.exit_code == 2 and "already holds epoch 1" in res.output, res.output
    stamp = (parts / "last.pt").stat().st_mtime_ns
    res = runner.invoke(app, [*base, "--out", str(parts)])  # afresh would write over epoch 1
    assert res.exit_code == 2 and "already holds a run" in res.output, res.output
    assert (parts / "last.pt").stat().st_mtime_ns == stamp
    res = runner.invoke(app, [*base, "--out", str(parts), "--resume"])
    assert res.exit_code == 0, res.output
    a, b = (json.loads((d / "test_metrics.json").read_text()) for d in (whole, parts))
    assert a["test_metrics"] == b["test_metrics"] and a["test_confusion"] == b["test_confusion"]
    ha, hb = (load_checkpoint(d / "last.pt")["history"] for d in (whole, parts))
    assert [h["train_loss"] for h in ha] == [h["train_loss"] for h in hb] and len(hb) == 2


def test_canvas_option_reaches_the_checkpoint(app, tiny_dataset, small_config, tmp_path):
    """``--canvas-mm H,W`` sets the model's input canvas (the run TOML's ``[model] canvas_mm``)."""
    out = tmp_path / "run"
    res = runner.invoke(
        app,
        [
            "train",
            str(tiny_dataset),
            "--out",
            str(out),
            "--config",
            str(small_config),
            "--no-progress",
            "--epochs",
            "1",
            "--canvas-mm",
            "60,150.5",
        ],
    )
    assert res.exit_code == 0, res.output
    assert load_checkpoint(out / "best.pt")["config"]["model"]["canvas_mm"] == [60.0, 150.5]
    assert "canvas_mm = [60.0, 150.5]" in (out / "run.toml").read_text()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["train", "{missing}", "--out", "{out}"], "no dataset or image folder"),
        (["train", "{data}", "--out", "{out}", "--arch", "resnet"], "unknown arch 'resnet'"),
        (["train", "{data}", "--out", "{out}", "--config", "{bad}"], "key 'train.learning_rate'"),
        (["evaluate", "{out}/none.pt", "--data", "{data}"], "no checkpoint"),
        (["evaluate", "{bad}", "{out}/../bad.toml", "--data", "{data}"], "is given twice"),
        (
            ["evaluate", "{out}/none.pt", "--data", "{data}", "--time-rounds", "0"],
            "time rounds must be a whole number >= 1",
        ),
        (
            ["evaluate", "{out}/none.pt", "--data", "{data}", "--time-runs", "0"],
            "--time-runs 1 or more",
        ),
        (["train", "{data}", "--out", "{bad}"], "bad.toml is a file, not a folder"),
        (["train", "{data}", "--out", "{bad}/run", "--arch", "bovw"], "is a file, not a folder"),
        (["predict", "--frame", "{bad}"], "--frame with --map"),
        (["train", "{data}", "--out", "{out}", "--precision", "fp16"], "precision 'fp16'"),
        (
            ["train", "{data}", "--out", "{out}", "--arch", "bovw", "--precision", "bf16"],
            "--precision does not apply",
        ),
        (["train", "{data}", "--out", "{out}", "--stop-after-epoch", "0"], "epochs are 1 to"),
        (
            ["train", "{data}", "--out", "{out}", "--epochs", "3", "--stop-after-epoch", "4"],
            "epochs are 1 to 3",
        ),
        (
            ["train", "{data}", "--out", "{out}", "--arch", "bovw", "--stop-after-epoch", "1"],
            "--stop-after-epoch does not apply",
        ),
        (
            [
                "train",
                "{data}",
                "--out",
                "{out}",
                "--stop-after-epoch",
                "1",
                "--cv-grid",
                "train.lr=0.1,0.01",
            ],
            "--stop-after-epoch with --cv-grid",
        ),
        (["train", "{data}", "--out", "{out}", "--canvas-mm", "229"], "give the canvas as H,W"),
        (["train", "{data}", "--out", "{out}", "--canvas-mm", "0,383"], "both > 0"),
        (
            ["train", "{data}", "--out", "{out}", "--arch", "bovw", "--canvas-mm", "229,383"],
            "--canvas-mm does not apply",
        ),
        (["train", "{data}", "--out", "{out}", "--device", "gpu"], "is not a training device"),
        (
            ["train", "{data}", "--out", "{out}", "--distill-from", "{out}/none.pt"],
            "no teacher checkpoint",
        ),
        (
            ["train", "{data}", "--out", "{out}", "--arch", "bovw", "--distill-from", "{bad}"],
            "--distill-from does not apply",
        ),
        (
            ["train", "{data}", "--out", "{out}", "--arch", "segnet", "--distill-from", "{bad}"],
            "needs a classifier",
        ),
        (
            [
                "train",
                "{data}",
                "--out",
                "{out}",
                "--distill-from",
                "{bad}",
                "--cv-grid",
                "train.lr=0.1,0.01",
            ],
            "--distill-from with --cv-grid",
        ),
        pytest.param(
            ["train", "{data}", "--out", "{out}", "--device", "cuda"],
            "sees no CUDA GPU",
            marks=pytest.mark.skipif(
                torch.cuda.is_available(), reason="this machine has a CUDA GPU"
            ),
        ),
        (
            ["train", "{data}", "--out", "{out}", "--arch", "bovw", "--device", "cuda"],
            "--device does not apply",
        ),
    ],
)
def test_errors_before_work(app, tiny_dataset, tmp_path, args, message):
    bad = tmp_path / "bad.toml"
    bad.write_text("[train]\nlearning_rate = 0.1\n")
    fill = {"missing": tmp_path / "nope", "out": tmp_path / "out", "data": tiny_dataset, "bad": bad}
    res = runner.invoke(app, [a.format(**fill) for a in args])
    assert res.exit_code == 2 and message in res.output, res.output
    assert not (tmp_path / "out").exists()  # nothing written
    assert bad.read_text() == "[train]\nlearning_rate = 0.1\n"  # nor overwritten


def test_the_cli_names_every_preset_and_classical_baseline():
    """The CLI's lists (kept import-free so --help stays fast) match the modules they mirror."""
    from learn import cli
    from learn.classical import CLASSICAL
    from learn.config import PRESET_OF_ARCH

    assert cli.PRESETS == tuple(PRESET_OF_ARCH) and cli.CLASSICAL == tuple(CLASSICAL)
