"""int8 files (`handskin quantize`, `learn.int8_file`): the saved network computes the same
bits as the one calibrated afresh, runs without the training data, is scored and predicted as
int8, and is refused, with nothing written over, where it does not fit."""

from __future__ import annotations

import json

import pytest
import torch
import typer
from typer.testing import CliRunner

from learn.cli import register
from learn.evaluate.scoring import Job, evaluate_job
from learn.infer.int8_file import calibration_images, int8_from_saved
from learn.infer.predict import load_predictor, read_sample
from learn.infer.quantize import int8_supported, quantize_int8
from learn.train.checkpoint import INT8_KEY, is_int8, load_checkpoint, model_from_checkpoint
from tactile.errors import ConfigError, DataError

pytestmark = pytest.mark.skipif(
    not int8_supported(), reason="PyTorch without the oneDNN quantized engine"
)


def _app() -> tuple[typer.Typer, CliRunner]:
    app = typer.Typer()
    register(app)
    return app, CliRunner()


@pytest.fixture(scope="module")
def int8_file(checkpoints, tmp_path_factory):
    """``handskin quantize`` of the tiny HandsNet, into a folder of its own."""
    app, runner = _app()
    out = tmp_path_factory.mktemp("int8") / "hn_int8.pt"
    res = runner.invoke(app, ["quantize", str(checkpoints["handsnet"]), "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "int8 HandsNet written to" in res.output and "same class as the float" in res.output
    return out


def test_saved_network_is_the_calibrated_one(checkpoints, tiny_dataset, int8_file, tmp_path):
    """The file's network gives bit-identical logits to `quantize_int8` on the same calibration
    draw (the reference, built independently here), also when the training data has moved
    away: the file needs no calibration images."""
    ckpt = load_checkpoint(int8_file)
    assert is_int8(ckpt) and "optimizer" not in ckpt
    assert ckpt[INT8_KEY]["calibration"]["data"] == str(tiny_dataset)
    model, run = model_from_checkpoint(load_checkpoint(checkpoints["handsnet"]))
    calib = calibration_images(tiny_dataset, run, None)
    assert ckpt[INT8_KEY]["calibration"]["images"] == len(calib)
    ref_net = quantize_int8(model, calib)
    x = calib[:8] * 0.7 + 0.1  # inputs other than the calibration images themselves
    with torch.no_grad():
        ref = ref_net(x)
        assert torch.equal(int8_from_saved(model, ckpt)(x), ref)
    moved = {**ckpt, "data": {**ckpt["data"], "path": str(tmp_path / "gone")}}
    torch.save(moved, tmp_path / "moved_int8.pt")
    sample = read_sample(tiny_dataset, 33)
    from_file = load_predictor(tmp_path / "moved_int8.pt").logits(sample.image)
    afresh = load_predictor(checkpoints["handsnet"], int8=True).logits(sample.image)
    assert torch.equal(from_file, afresh)
    assert not torch.equal(from_file, load_predictor(checkpoints["handsnet"]).logits(sample.image))


def test_evaluate_scores_the_file_as_int8(checkpoints, tiny_dataset, int8_file, tmp_path):
    """``handskin evaluate FILE``: an int8 row, the same confusion matrix as ``--int8`` on the
    float checkpoint, the report saying where its ranges came from."""
    app, runner = _app()
    md = tmp_path / "r.md"
    res = runner.invoke(app, ["evaluate", str(tiny_dataset), str(int8_file), "--out", str(md)])
    assert res.exit_code == 0, res.output
    (row,) = json.loads(md.with_suffix(".json").read_text())
    assert row["int8"]["saved"] and row["int8"]["calibration_data"] == str(tiny_dataset)
    direct = evaluate_job(Job((checkpoints["handsnet"],), int8=True), tiny_dataset, time_runs=3)
    assert row["cm"] == direct["cm"]
    assert "| HandsNet, int8" in md.read_text() and "saved by handskin quantize" in md.read_text()


def test_bad_input_refused(checkpoints, tiny_dataset, int8_file, tmp_path):
    """Refused before any work, naming the fix; a float checkpoint at --out is left as it was."""
    app, runner = _app()
    hn, seg = str(checkpoints["handsnet"]), str(checkpoints["segnet"])
    float_copy = tmp_path / "float.pt"
    float_copy.write_bytes(checkpoints["handsnet"].read_bytes())
    before = float_copy.read_bytes()
    for args, message in (
        (["quantize", seg, "--out", str(tmp_path / "s.pt")], "covers HandsNet"),
        (["quantize", str(int8_file), "--out", str(tmp_path / "q.pt")], "is an int8 network"),
        (["quantize", hn, "--out", hn], "the checkpoint itself"),
        (["quantize", hn, "--out", str(float_copy)], "not written over"),
        (["quantize", hn, "--out", str(tmp_path / "q.pt"), "--images", "8"], "at least 16"),
        (
            [
                "quantize",
                hn,
                "--out",
                str(tmp_path / "q.pt"),
                "--calibration",
                str(tmp_path / "nope"),
            ],
            "not found",
        ),
        (
            [
                "predict",
                str(tiny_dataset),
                "--sample",
                "3",
                "--classifier",
                str(int8_file),
                "--int8",
                "--calibration",
                str(tiny_dataset),
            ],
            "drop --calibration",
        ),
        (
            [
                "evaluate",
                str(tiny_dataset),
                str(int8_file),
                hn,
                "--ensemble",
                "--out",
                str(tmp_path / "e.md"),
            ],
            "an ensemble averages float networks",
        ),
        (
            [
                "evaluate",
                str(tiny_dataset),
                str(int8_file),
                "--int8",
                "--out",
                str(tmp_path / "e.md"),
            ],
            "scored as int8 without it",
        ),
    ):
        res = runner.invoke(app, args)
        assert res.exit_code == 2 and message in res.output, (args, res.output)
    assert float_copy.read_bytes() == before
    assert not (tmp_path / "q.pt").exists() and not (tmp_path / "e.md").exists()
    with pytest.raises(ConfigError, match="runs float networks"):
        model_from_checkpoint(load_checkpoint(int8_file))


def test_unloadable_state_names_the_fix(checkpoints, int8_file):
    """A stored network that does not fit this PyTorch's quantized graph (here: a layer
    missing) is a DataError telling to quantize again."""
    ckpt = load_checkpoint(int8_file)
    del ckpt[INT8_KEY]["model"]["body.1.7.scale"]
    model, _ = model_from_checkpoint(load_checkpoint(checkpoints["handsnet"]))
    with pytest.raises(DataError, match="handskin quantize"):
        int8_from_saved(model, ckpt)
