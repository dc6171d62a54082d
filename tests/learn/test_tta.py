"""Test-time flips (`learn.tta`): against a slow image-by-image, view-by-view reference, closed
forms for flip-symmetric networks, and through `handskin evaluate` / `predict --tta`."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
import typer
from torch import nn
from typer.testing import CliRunner

from learn.cli import register
from learn.evaluate.scoring import Job, evaluate_job
from learn.infer.ensemble import FlipTTA
from learn.infer.predict import load_predictor
from learn.inputs import VIEW_DIMS, flip_view
from learn.models import create_model
from learn.train.checkpoint import load_checkpoint, save_checkpoint

SIZE = (32, 40)


def slow_reference(model: nn.Module, x: torch.Tensor, views: list[int]) -> torch.Tensor:
    """log of the mean softmax, one image and one view at a time, flips written out with numpy
    index reversal (a view's output of a segmenter is reversed back the same way)."""
    rev = {
        0: (slice(None), slice(None)),
        1: (slice(None), slice(None, None, -1)),
        2: (slice(None, None, -1), slice(None)),
        3: (slice(None, None, -1),) * 2,
    }
    out = []
    with torch.no_grad():
        for img in x.numpy():  # (1, h, w)
            probs = []
            for v in views:
                seen = np.ascontiguousarray(img[(slice(None), *rev[v])])
                p = model(torch.from_numpy(seen)[None])[0].softmax(0).numpy()
                probs.append(np.ascontiguousarray(p[(slice(None), *rev[v])]) if p.ndim == 3 else p)
            out.append(np.log(np.mean(probs, axis=0)))
    return torch.from_numpy(np.stack(out))


@pytest.mark.parametrize(
    ("arch", "views"),
    [("handsnet", [0, 1, 2]), ("segnet", [0, 1, 2]), ("fcn16s", [0, 1, 2, 3]), ("segnet", [0, 3])],
)
def test_matches_the_slow_reference(arch, views):
    torch.manual_seed(0)
    kw = {"input_size": SIZE} if arch == "handsnet" else {"width": 0.0625}
    model = create_model(arch, num_classes=2 if arch == "handsnet" else 7, **kw).eval()
    x = torch.rand(3, 1, *SIZE)
    with torch.no_grad():
        got = FlipTTA(model, views)(x)
    torch.testing.assert_close(got, slow_reference(model, x, views).float(), atol=2e-5, rtol=1e-4)
    assert torch.allclose(got.exp().sum(1), torch.ones(()))  # a distribution per image or pixel


def test_flip_symmetric_networks_are_unchanged():
    """A 1 x 1 convolution commutes with flips, and a global mean is blind to them: test-time
    flips then give the network's own log-softmax."""
    torch.manual_seed(1)
    x = torch.rand(4, 1, *SIZE)
    pixelwise = nn.Conv2d(1, 7, 1)
    pooled = nn.Sequential(
        nn.Conv2d(1, 5, 1), nn.AdaptiveAvgPool2d(1), nn.Flatten(), nn.Linear(5, 2)
    )
    with torch.no_grad():
        for net in (pixelwise, pooled):
            got = FlipTTA(net, (0, 1, 2, 3))(x)
            torch.testing.assert_close(got, net(x).log_softmax(1), atol=1e-5, rtol=1e-5)


@pytest.mark.parametrize("view", sorted(VIEW_DIMS))
def test_numpy_and_torch_flips_agree_with_index_reversal(view):
    """The datasets' numpy flip and the training / TTA torch flip both give the written-out
    index reversal of each view, on (H, W) and (C, H, W) arrays."""
    rev_rows, rev_cols = view in (2, 3), view in (1, 3)
    for shape in ((5, 7), (2, 5, 7)):
        a = np.arange(np.prod(shape)).reshape(shape)
        want = a[..., :: -1 if rev_rows else 1, :][..., :: -1 if rev_cols else 1]
        np.testing.assert_array_equal(flip_view(a, view), want)
        np.testing.assert_array_equal(flip_view(torch.from_numpy(a), view).numpy(), want)


@pytest.mark.parametrize("views", [(0,), (0, 0), (0, 5), ()])
def test_bad_views(views):
    with pytest.raises(ValueError, match="two or more distinct"):
        FlipTTA(nn.Conv2d(1, 2, 1), views)


def without_flips(path, tmp_path):
    """A copy of checkpoint ``path`` whose run config says it was trained without flips."""
    ckpt = load_checkpoint(path)
    ckpt["config"] = dict(ckpt["config"], flips=False)
    return save_checkpoint(ckpt, tmp_path / "noflips.pt")


def test_evaluate_with_test_time_flips(checkpoints, tiny_dataset, tmp_path, near_ties):
    """`handskin evaluate --tta`: a second row per network, scored with the flips; its
    confusion matrix is the slow reference's; a network trained without flips is refused before
    any report is written."""
    from learn.data.load import materialize, open_split
    from learn.metrics import confusion_matrix
    from learn.train.checkpoint import model_from_checkpoint

    # HandsNet: SegNet's unpooling breaks max-pool ties by batch layout, which moves near-tied
    # pixels of a barely trained net; the classifier's decision differs only at near ties
    row = evaluate_job(Job((checkpoints["handsnet"],), tta=True), tiny_dataset, time_runs=3)
    assert row["tta_views"] == [0, 1, 2] and row["ms_per_image"]["fast"] > 0
    model, run = model_from_checkpoint(load_checkpoint(checkpoints["handsnet"]))
    test = materialize(
        open_split(tiny_dataset, "test", "classify", run.model.input_size, None, run.train.seed),
        "test",
        False,
    )
    scores = slow_reference(model, test.x, [0, 1, 2])
    near_ties.assert_cm(row["cm"], confusion_matrix(test.y, scores.argmax(1), 2), scores)

    app = typer.Typer()
    register(app)
    md = tmp_path / "r.md"
    args = [
        "evaluate",
        str(tiny_dataset),
        str(checkpoints["handsnet"]),
        str(checkpoints["segnet"]),
        "--out",
        str(md),
        "--tta",
    ]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    rows = json.loads(md.with_suffix(".json").read_text())
    assert [(r["arch"], r["tta_views"]) for r in rows] == [
        ("handsnet", None),
        ("handsnet", [0, 1, 2]),
        ("segnet", None),
        ("segnet", [0, 1, 2]),
    ]
    text = md.read_text()
    assert "| HandsNet, flips |" in text and "| SegNet, flips |" in text
    assert "Test-time flips: the mean softmax over views [0, 1, 2]." in text
    bad = without_flips(checkpoints["segnet"], tmp_path)
    md2 = tmp_path / "r2.md"
    res = CliRunner().invoke(
        app,
        [
            "evaluate",
            str(tiny_dataset),
            str(checkpoints["handsnet"]),
            str(bad),
            "--out",
            str(md2),
            "--tta",
        ],
    )
    assert res.exit_code == 2 and "trained without flips" in res.output, res.output
    assert not md2.exists()


def test_predict_with_test_time_flips(checkpoints, tiny_dataset, tmp_path):
    """`load_predictor(tta=True)`: probabilities are the mean of the three views' softmax."""
    plain, tta = (load_predictor(checkpoints["handsnet"], t) for t in (False, True))
    image = (np.random.default_rng(0).random((40, 60)) * 255).astype(np.uint8)
    views = [image, image[:, ::-1], image[::-1]]
    mean = torch.stack([plain.logits(v).softmax(0) for v in views]).mean(0)
    torch.testing.assert_close(tta.logits(image).softmax(0), mean, atol=1e-3, rtol=1e-3)
    with pytest.raises(Exception, match="trained without flips"):
        load_predictor(without_flips(checkpoints["segnet"], tmp_path), tta=True)
