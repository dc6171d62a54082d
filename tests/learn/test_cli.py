"""`handskin train / evaluate / predict` through typer's CliRunner on a local app."""

from __future__ import annotations

import json

import numpy as np
import pytest
import typer
from typer.testing import CliRunner

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
    path.write_text('threads = 1\n[model]\ninput_size = [32, 48]\n[train]\nepochs = 2\n'
                    'batch_size = 16\n')  # fmt: skip
    return path


def test_train_evaluate_predict(app, tiny_dataset, small_config, checkpoints, tmp_path):
    out = tmp_path / "run"
    res = runner.invoke(app, ["train", str(tiny_dataset), "--out", str(out), "--config",
                              str(small_config), "--no-progress", "--seed", "1"])  # fmt: skip
    assert res.exit_code == 0, res.output
    for name in ("best.pt", "last.pt", "curves.png", "run.toml", "test_metrics.json"):
        assert (out / name).is_file(), name
    report = json.loads((out / "test_metrics.json").read_text())
    assert report["seed"] == 1 and "torch" in report["versions"]
    assert "accuracy" in report["test_metrics"]
    md = tmp_path / "report.md"
    res = runner.invoke(app, ["evaluate", str(out / "best.pt"), str(checkpoints["segnet"]),
                              "--data", str(tiny_dataset), "--report", str(md)])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "Table 3" in md.read_text() and md.with_suffix(".json").is_file()
    frame = tmp_path / "frame.npy"
    np.save(frame, open_dataset(tiny_dataset).raw[2])
    res = runner.invoke(app, ["predict", "--frame", str(frame), "--map", str(tiny_dataset),
                              "--classifier", str(out / "best.pt"), "--segmenter",
                              str(checkpoints["segnet"]), "--png",
                              str(tmp_path / "p.png")])  # fmt: skip
    assert res.exit_code == 0, res.output
    assert "probability" in res.output and "palm" in res.output and (tmp_path / "p.png").is_file()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["train", "{missing}", "--out", "{out}"], "no dataset or image folder"),
        (["train", "{data}", "--out", "{out}", "--arch", "resnet"], "unknown arch 'resnet'"),
        (["train", "{data}", "--out", "{out}", "--config", "{bad}"], "key 'train.learning_rate'"),
        (["evaluate", "{out}/none.pt", "--data", "{data}"], "no checkpoint"),
        (["train", "{data}", "--out", "{bad}"], "bad.toml is a file, not a folder"),
        (["train", "{data}", "--out", "{bad}/run", "--arch", "bovw"], "is a file, not a folder"),
        (["predict", "--frame", "{bad}"], "--frame with --map"),
        (["train", "{data}", "--out", "{out}", "--precision", "fp16"], "precision 'fp16'"),
        (["train", "{data}", "--out", "{out}", "--arch", "bovw", "--precision", "bf16"],
         "--precision does not apply"),
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
