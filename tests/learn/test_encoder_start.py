"""--pretrain-encoder (a segmenter's default on a handskin dataset): a vgg16 classifier trained
first into OUT/vgg16 starts the segmenter's encoder; its recipe is the one docs/learning.md
measured; --no-pretrain-encoder trains from scratch; bad combinations are refused first."""

from __future__ import annotations

import pytest
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
    from learn.cli import resolve_run
    from learn.encoder_start import encoder_run

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
            "--no-pretrain-encoder",
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
    # a run from scratch resumes from scratch by default, and refuses the encoder
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
    res = _train([*scratch_args, "--pretrain-encoder"])
    assert res.exit_code != 0 and "--no-pretrain-encoder" in res.output, res.output
    res = _train(scratch_args)
    assert res.exit_code == 0, res.output
    assert not (tmp_path / "scratch" / "vgg16").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--arch", "handsnet"], "starts a segmenter"),
        (["--arch", "segnet", "--init", "CKPT"], "give one of the two"),
        (["--arch", "segnet", "--cv-grid", "train.lr=0.01,0.001"], "would not be held out"),
        (["--arch", "bovw"], "does not apply to --arch bovw"),
    ],
)
def test_bad_combinations_are_refused_before_any_work(
    tiny_dataset, checkpoints, tmp_path, args, message
):
    args = [str(checkpoints["segnet"]) if a == "CKPT" else a for a in args]
    out = tmp_path / "run"
    res = _train([tiny_dataset, "--out", out, *args, "--pretrain-encoder"])
    assert res.exit_code != 0 and message in res.output, res.output
    assert not out.exists()


def test_an_image_folder_is_refused_and_not_pretrained_by_default(tiny_dataset, tmp_path):
    from learn.cli import resolve_run
    from learn.encoder_start import check_pretrain, wanted
    from tactile.errors import ConfigError

    (tmp_path / "imgs").mkdir()
    seg = resolve_run("segnet", None, {}, False)
    with pytest.raises(ConfigError, match="needs a handskin dataset"):
        check_pretrain(seg, tmp_path / "imgs", None, None)
    assert not wanted(None, seg, tmp_path / "imgs", None, None, tmp_path / "o", False)
    assert wanted(None, seg, tiny_dataset, None, None, tmp_path / "o", False)
    assert not wanted(None, seg, tiny_dataset, tmp_path / "x.pt", None, tmp_path / "o", False)
    assert not wanted(
        None,
        resolve_run("handsnet", None, {}, False),
        tiny_dataset,
        None,
        None,
        tmp_path / "o",
        False,
    )
