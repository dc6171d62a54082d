"""Ensembles: the mean softmax of several networks, in `handskin evaluate --ensemble` and in
`handskin predict` with a repeated --segmenter; scores against a numpy reference; members that
cannot share one input are refused before any work."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import typer
from typer.testing import CliRunner

from learn.cli import register
from learn.data.load import load_data, materialize, open_split
from learn.evaluate.scoring import Job, evaluate_job
from learn.infer.ensemble import MeanSoftmax, load_members
from learn.infer.predict import load_predictor
from learn.inputs import flip_view
from learn.train.checkpoint import load_checkpoint, model_from_checkpoint, save_checkpoint
from learn.train.loop import fit
from tactile.errors import ConfigError


@pytest.fixture(scope="module")
def fcn(tiny_dataset, tiny_run, tmp_path_factory):
    """An FCN-16s trained for two epochs on the tiny dataset: a second segmenter."""
    torch.set_num_threads(1)
    run = tiny_run("fcn16s", epochs=2)
    folder = tmp_path_factory.mktemp("runs") / "fcn16s"
    fit(run, load_data(tiny_dataset, run), folder, progress=False)
    return folder / "best.pt"


def reseeded(path, tmp_path, seed: int):
    """A copy of a checkpoint with every float weight moved by seeded noise: another network."""
    ckpt = load_checkpoint(path)
    gen = torch.Generator().manual_seed(seed)
    ckpt["model"] = {
        k: v + 0.05 * torch.randn(v.shape, generator=gen) if v.is_floating_point() else v
        for k, v in ckpt["model"].items()
    }
    return save_checkpoint(ckpt, tmp_path / f"reseeded{seed}.pt")


def numpy_mean_softmax(paths, x: torch.Tensor, views=(0,)) -> np.ndarray:
    """The mean over networks and views of each network's softmax, in float64 numpy."""
    probs = []
    for p in paths:
        model, _ = model_from_checkpoint(load_checkpoint(p))
        with torch.no_grad():
            for v in views:
                z = flip_view(model(flip_view(x, v)), v).double().numpy()
                e = np.exp(z - z.max(1, keepdims=True))
                probs.append(e / e.sum(1, keepdims=True))
    return np.mean(probs, axis=0)


def test_mean_softmax_is_the_mean_of_the_members():
    torch.manual_seed(0)
    nets = [torch.nn.Linear(5, 3), torch.nn.Linear(5, 3), torch.nn.Linear(5, 3)]
    x = torch.randn(4, 5)
    out = MeanSoftmax(nets)(x)
    with torch.no_grad():
        expected = (
            sum(np.exp(n(x).numpy()) / np.exp(n(x).numpy()).sum(1, keepdims=True) for n in nets) / 3
        )
    np.testing.assert_allclose(out.exp().detach().numpy(), expected, rtol=1e-5)
    with pytest.raises(ConfigError, match="two or more"):
        MeanSoftmax(nets[:1])


def test_members_that_cannot_share_an_input_are_refused(checkpoints, fcn, tmp_path):
    with pytest.raises(ConfigError, match="differ in task"):
        load_members([checkpoints["handsnet"], checkpoints["segnet"]])
    with pytest.raises(ConfigError, match="twice"):
        load_members([fcn, fcn])
    with pytest.raises(ConfigError, match="two or more"):
        load_members([fcn])
    ckpt = load_checkpoint(fcn)
    model = dict(ckpt["config"]["model"], input_size=[24, 36])
    other = save_checkpoint(
        dict(ckpt, config=dict(ckpt["config"], model=model)), tmp_path / "small.pt"
    )
    with pytest.raises(ConfigError, match=r"input size .* Fix"):
        load_members([checkpoints["segnet"], other])


def test_evaluate_ensemble_matches_a_numpy_reference(
    checkpoints, tiny_dataset, tmp_path, near_ties
):
    """The ensemble row's confusion matrix is the one of argmax(mean softmax), unpressed pixels
    background, counted here with numpy; with flips, the mean runs over members and views.

    The members are the briefly trained SegNet and a copy with seeded noise on its weights: two
    networks of like confidence, so the mean sides with each on many pixels (about 1,000-3,400
    of 5,492 on an AMD EPYC). With the 2-epoch FCN-16s as the second member the mean equalled
    the FCN alone on every pixel there, and the check could not tell the mean from it."""
    paths = [checkpoints["segnet"], reseeded(checkpoints["segnet"], tmp_path, 1)]
    _, run = model_from_checkpoint(load_checkpoint(paths[0]))
    test = materialize(
        open_split(tiny_dataset, "test", "segment", run.model.input_size, None, run.train.seed),
        "test",
        False,
    )
    differs = dict.fromkeys(paths, False)
    for tta, views in ((False, (0,)), (True, (0, 1, 2))):
        row = evaluate_job(Job(tuple(paths), tta=tta), tiny_dataset, time_runs=2)
        probs = numpy_mean_softmax(paths, test.x, views)
        unpressed = test.x[:, 0].numpy() == 0
        probs = np.where(unpressed[:, None], np.eye(7)[0][:, None, None], probs)  # background
        pred = probs.argmax(1)
        truth = test.y.numpy()
        cm = np.bincount(7 * truth.ravel() + pred.ravel(), minlength=49).reshape(7, 7)
        near_ties.assert_cm(row["cm"], cm, probs)
        for alone in paths:  # where the mean decides differently from a network alone
            one = numpy_mean_softmax([alone], test.x, views).argmax(1)
            one[test.x[:, 0].numpy() == 0] = 0
            differs[alone] = differs[alone] or bool((one != pred).any())
        assert row["arch"] == "ensemble" and [m["arch"] for m in row["members"]] == [
            "segnet",
            "segnet",
        ]
        assert row["tta_views"] == ([0, 1, 2] if tta else None)
        assert row["ms_per_image"]["fast"] > 0
    assert all(differs.values())  # the check can tell the mean from either network alone


def test_cli_evaluate_and_predict_with_an_ensemble(checkpoints, fcn, tiny_dataset, tmp_path):
    app = typer.Typer()
    register(app)
    md = tmp_path / "r.md"
    args = [
        "evaluate",
        str(tiny_dataset),
        str(checkpoints["handsnet"]),
        str(checkpoints["segnet"]),
        str(fcn),
        "--out",
        str(md),
        "--ensemble",
    ]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    rows = json.loads(md.with_suffix(".json").read_text())
    assert [r["arch"] for r in rows] == ["handsnet", "segnet", "fcn16s", "ensemble"]
    text = md.read_text()
    assert "| Ensemble (SegNet + FCN) |" in text and f"- member `{fcn}`" in text
    # One network per task: nothing to average, refused before any report is written.
    md2 = tmp_path / "r2.md"
    res = CliRunner().invoke(
        app,
        [
            "evaluate",
            str(tiny_dataset),
            str(checkpoints["handsnet"]),
            str(checkpoints["segnet"]),
            "--out",
            str(md2),
            "--ensemble",
        ],
    )
    assert res.exit_code == 2 and "1 classify, 1 segment" in res.output, res.output
    assert not md2.exists()

    # predict: two classifiers averaged give the mean of their probabilities.
    other = reseeded(checkpoints["handsnet"], tmp_path, 1)
    both = load_predictor([checkpoints["handsnet"], other])
    image = (np.random.default_rng(0).random((40, 60)) * 255).astype(np.uint8)
    mean = sum(load_predictor(p).logits(image).softmax(0) for p in (checkpoints["handsnet"], other))
    torch.testing.assert_close(both.logits(image).softmax(0), mean / 2, atol=1e-4, rtol=1e-4)
    png = tmp_path / "pred.png"
    res = CliRunner().invoke(
        app,
        [
            "predict",
            str(tiny_dataset),
            "--sample",
            "3",
            "--segmenter",
            str(checkpoints["segnet"]),
            "--segmenter",
            str(fcn),
            "--png",
            str(png),
        ],
    )
    assert res.exit_code == 0 and png.exists(), res.output
    res = CliRunner().invoke(
        app,
        [
            "predict",
            str(tiny_dataset),
            "--sample",
            "3",
            "--segmenter",
            str(checkpoints["segnet"]),
            "--segmenter",
            str(checkpoints["handsnet"]),
        ],
    )
    assert res.exit_code == 2 and "differ in task" in res.output, res.output
