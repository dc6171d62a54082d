"""The encoder start (a segmenter's default on a handskin dataset): a vgg16 classifier trained
first into OUT/vgg16 starts the segmenter's encoder; its recipe is the documented one;
--from-scratch trains from scratch."""

from __future__ import annotations

import torch
import typer
from typer.testing import CliRunner

from learn.cli import register

TINY = "threads = 1\n[model]\ninput_size = [32, 48]\nwidth = 0.125\n[train]\nepochs = 1\n"


def _train(args: list[str]):
    app = typer.Typer()
    register(app)
    return CliRunner().invoke(app, ["train", *map(str, args), "--no-progress"])


def test_the_classifier_is_the_documented_recipe(tmp_path):
    """The classifier's run equals the one docs/learning.md trained by hand: the vgg16 preset
    with `epochs = 20, lr_drop_period_epochs = 14` in a run TOML (here at seed 3)."""
    from learn.cli.train import resolve_run
    from learn.train.encoder import encoder_run

    toml = tmp_path / "vgg.toml"
    toml.write_text("[train]\nepochs = 20\nlr_drop_period_epochs = 14\nseed = 3\n")
    by_hand = resolve_run("vgg16", toml, {}, False)
    assert encoder_run(resolve_run("segnet", None, {"seed": 3}, False)) == by_hand


def test_the_segmenter_starts_from_the_classifier_trained_first(tiny_dataset, tmp_path):
    config = tmp_path / "run.toml"
    config.write_text(TINY)
    out = tmp_path / "seg"
    res = _train([tiny_dataset, "--out", out, "--arch", "segnet", "--config", config])  # default
    assert res.exit_code == 0, res.output
    vgg = torch.load(out / "vgg16" / "best.pt", weights_only=False)
    seg = torch.load(out / "best.pt", weights_only=False)
    assert vgg["config"]["model"]["arch"] == "vgg16" and vgg["config"]["model"]["width"] == 0.125
    assert vgg["config"]["train"]["epochs"] == 20 and vgg["data"]["path"] == str(tiny_dataset)
    assert seg["init"] == str(out / "vgg16" / "best.pt")
    said = " ".join(res.output.split())  # the console wraps long lines
    assert f"segnet: first a vgg16 classifier in {out / 'vgg16'}" in said
    assert "78 of 152 tensors loaded; classifier, decoder start fresh" in said
    # the first convolution stays one epoch from the classifier's; a twin from scratch does not
    res = _train(
        [
            tiny_dataset,
            "--out",
            tmp_path / "scratch",
            "--arch",
            "segnet",
            "--config",
            config,
            "--from-scratch",
        ]
    )
    assert res.exit_code == 0, res.output
    scratch = torch.load(tmp_path / "scratch" / "best.pt", weights_only=False)
    assert scratch["init"] == "random" and not (tmp_path / "scratch" / "vgg16").exists()
    first = next(k for k in vgg["model"] if k.startswith("encoder.") and k.endswith("weight"))
    far = [float((net["model"][first] - vgg["model"][first]).norm()) for net in (seg, scratch)]
    assert far[0] < far[1] / 4, far
    # rerun with --resume: the finished classifier is reused, not trained again
    stamp = (out / "vgg16" / "best.pt").stat().st_mtime_ns
    config.write_text(TINY.replace("epochs = 1", "epochs = 2"))
    res = _train([tiny_dataset, "--out", out, "--arch", "segnet", "--config", config, "--resume"])
    assert res.exit_code == 0, res.output
    assert (out / "vgg16" / "best.pt").stat().st_mtime_ns == stamp
    assert torch.load(out / "last.pt", weights_only=False)["epoch"] == 2  # epochs done
    # a run from scratch resumes from scratch, as it started
    scratch_args = [
        tiny_dataset,
        "--out",
        tmp_path / "scratch",
        "--arch",
        "segnet",
        "--config",
        config,
        "--resume",
    ]
    res = _train(scratch_args)
    assert res.exit_code == 0, res.output
    assert not (tmp_path / "scratch" / "vgg16").exists()


def test_the_encoder_start_applies_to_segmenters_on_a_dataset_only(tiny_dataset, tmp_path):
    """By default a segmenter on a handskin dataset; not with --from-scratch, a classifier, a
    start of its own (--init), a cross-validation, or an image folder."""
    from learn.cli.train import resolve_run
    from learn.train.encoder import wanted

    (tmp_path / "imgs").mkdir()
    seg, out = resolve_run("segnet", None, {}, False), tmp_path / "o"
    assert wanted(False, seg, tiny_dataset, None, None, out, False)
    assert not wanted(True, seg, tiny_dataset, None, None, out, False)
    assert not wanted(False, seg, tmp_path / "imgs", None, None, out, False)
    assert not wanted(False, seg, tiny_dataset, tmp_path / "x.pt", None, out, False)
    assert not wanted(False, seg, tiny_dataset, None, "train.lr=0.1,0.01", out, False)
    handsnet = resolve_run("handsnet", None, {}, False)
    assert not wanted(False, handsnet, tiny_dataset, None, None, out, False)
