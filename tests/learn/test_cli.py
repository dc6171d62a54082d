"""`handskin train / evaluate / predict` through typer's CliRunner on a local app."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import typer
from typer.testing import CliRunner

from learn.cli import register
from learn.train.checkpoint import load_checkpoint
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
            str(tiny_dataset),
            str(out / "best.pt"),
            str(checkpoints["segnet"]),
            "--out",
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
        (
            ["train", "{data}", "--out", "{out}", "--arch", "resnet"],
            "--arch 'resnet': choose one of",
        ),
        (["train", "{data}", "--out", "{out}", "--config", "{bad}"], "key 'train.learning_rate'"),
        (["evaluate", "{data}", "{out}/none.pt"], "no checkpoint"),
        (["evaluate", "{data}", "{bad}", "{out}/../bad.toml"], "is given twice"),
        (
            ["evaluate", "{data}", "{out}/none.pt", "--time-rounds", "0"],
            "time rounds must be a whole number >= 1",
        ),
        (
            ["evaluate", "{data}", "{out}/none.pt", "--time-runs", "0"],
            "--time-runs 1 or more",
        ),
        (["train", "{data}", "--out", "{bad}"], "bad.toml is a file, not a folder"),
        (["train", "{data}", "--out", "{bad}/run", "--arch", "bovw"], "is a file, not a folder"),
        (["predict", "{bad}"], "or a frame (.csv, .npy)"),
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


def test_the_cli_names_every_classical_baseline():
    """The CLI's list (kept import-free so --help stays fast) matches the module it mirrors."""
    from learn.classical.svm import CLASSICAL
    from learn.cli import train as cli

    assert cli.CLASSICAL == tuple(CLASSICAL)


def _digest(folder) -> dict:
    import hashlib

    return {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(folder.iterdir())}


def test_a_run_folder_is_never_written_over(app, tiny_dataset, tiny_writer, small_config, tmp_path):
    """best.pt without last.pt is refused by a fresh start and by --resume, nothing changed;
    --resume with nothing to resume is refused, nothing written; --resume on other data is
    refused, naming both."""
    base = ["train", str(tiny_dataset), "--config", str(small_config), "--no-progress"]
    run = tmp_path / "run"
    res = runner.invoke(app, [*base, "--out", str(run), "--resume", "--epochs", "1"])
    assert res.exit_code == 2 and "holds no last.pt, so there is no run to resume" in res.output
    assert not run.exists()
    res = runner.invoke(app, [*base, "--out", str(run), "--epochs", "1"])
    assert res.exit_code == 0, res.output
    (run / "last.pt").unlink()
    before = _digest(run)
    for extra in ([], ["--resume"]):
        res = runner.invoke(app, [*base, "--out", str(run), *extra])
        assert res.exit_code == 2 and "holds best.pt but no last.pt" in res.output, res.output
        assert "Fix: move it away first" in res.output and _digest(run) == before
    other = tiny_writer(tmp_path / "other", list(range(0, 48, 2)))
    run2 = tmp_path / "run2"
    res = runner.invoke(app, [*base, "--out", str(run2), "--stop-after-epoch", "1"])
    assert res.exit_code == 0, res.output
    before = _digest(run2)
    resumed = ["train", str(other), "--config", str(small_config), "--out", str(run2), "--resume"]
    res = runner.invoke(app, resumed)
    assert res.exit_code == 2 and str(tiny_dataset) in res.output and str(other) in res.output
    assert _digest(run2) == before


def test_resume_refuses_a_dataset_regenerated_at_the_same_path(
    app, tiny_writer, small_config, tmp_path
):
    """A stopped run, its dataset generated again at the same path with other settings (another
    fingerprint): --resume is refused naming both fingerprints, the run folder unchanged."""
    import shutil

    from learn.data.load import fingerprint

    data, run = tmp_path / "data", tmp_path / "run"
    tiny_writer(data, list(range(48)))
    first = fingerprint(data)
    base = ["train", str(data), "--config", str(small_config), "--out", str(run), "--no-progress"]
    res = runner.invoke(app, [*base, "--stop-after-epoch", "1"])
    assert res.exit_code == 0, res.output
    before = _digest(run)
    shutil.rmtree(data)
    tiny_writer(data, list(range(48)), split="greedy")  # the same samples, another manifest
    assert fingerprint(data) != first
    res = runner.invoke(app, [*base, "--resume"])
    assert res.exit_code == 2 and first[:12] in res.output and fingerprint(data)[:12] in res.output
    assert "another --out" in res.output and _digest(run) == before
    from learn.train.checkpoint import load_checkpoint, save_checkpoint

    older = load_checkpoint(run / "last.pt")  # as written before checkpoints kept fingerprints
    del older["data"]["fingerprint"]
    save_checkpoint(older, run / "last.pt")
    res = runner.invoke(app, [*base, "--resume"])
    assert res.exit_code == 0, res.output


def test_one_class_training_data_is_refused(app, tiny_writer, small_config, tmp_path):
    only_objects = tiny_writer(tmp_path / "objects", list(range(24, 48)))
    out = tmp_path / "run"
    res = runner.invoke(app, ["train", str(only_objects), "--out", str(out), "--no-progress"])
    assert res.exit_code == 2 and "holds non_hand only" in res.output, res.output
    assert not out.exists()


def test_unreadable_images_in_a_folder_are_skipped_and_listed(app, small_config, tmp_path):
    from PIL import Image

    rng = np.random.default_rng(0)
    for cls in ("hand", "other"):
        (tmp_path / "imgs" / cls).mkdir(parents=True)
        for k in range(12):
            img = (rng.random((28, 50)) * 255).astype(np.uint8)
            Image.fromarray(img).save(tmp_path / "imgs" / cls / f"{k}.png")
    (tmp_path / "imgs" / "hand" / "notes.png").write_text("not an image")
    whole = (tmp_path / "imgs" / "other" / "0.png").read_bytes()
    (tmp_path / "imgs" / "other" / "cut.png").write_bytes(whole[: len(whole) // 2])
    out = tmp_path / "run"
    args = ["train", str(tmp_path / "imgs"), "--out", str(out), "--config", str(small_config)]
    res = runner.invoke(app, [*args, "--epochs", "1", "--no-progress"])
    assert res.exit_code == 0, res.output
    assert "2 of 26 image files" in res.output and "notes.png" in res.output
    assert "cut.png" in res.output
