"""`handskin experiment pareto` on the tiny dataset: the front against a brute-force dominance
check, the budgeted trainer's step count and seeding, and one end-to-end run (given main models,
warm-started sizes, the full map, widths, BoVW and VGG16 + SVM) checked against independent
evaluations; bad input fails before any work."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import typer
from matplotlib.image import imread
from typer.testing import CliRunner

from experiments import pareto as P
from experiments.cli import register
from experiments.pareto_front import front_line, pareto_mask
from experiments.pareto_runs import train_budgeted
from learn.data.load import load_data
from learn.inputs import net_input
from learn.train.checkpoint import load_checkpoint, model_from_checkpoint
from tactile.dataset.reader import DatasetReader

TINY = P.ParetoSettings(
    sizes=("24x36", "full"),
    widths=(0.125,),
    seg_widths=(),
    seg_sizes=("24x36",),
    budget_min=5.0,
    max_steps=2,
    max_test=None,
    time_runs=2,
    threads=1,
)


def dominated(ms: np.ndarray, score: np.ndarray, i: int) -> bool:
    """Slow reference: some other point is at least as fast and as good, and better in one."""
    other = np.arange(len(ms)) != i
    no_worse = (ms <= ms[i]) & (score >= score[i])
    better = (ms < ms[i]) | (score > score[i])
    return bool(np.any(other & no_worse & better))


def test_pareto_mask_matches_brute_force():
    rng = np.random.default_rng(0)
    for _ in range(50):
        ms = rng.integers(1, 6, 12).astype(float)  # few values: ties in time and in score
        score = rng.integers(0, 5, 12).astype(float)
        score[rng.random(12) < 0.1] = np.nan
        expected = [
            np.isfinite(score[i]) and not dominated(ms, np.nan_to_num(score, nan=-1), i)
            for i in range(12)
        ]
        assert pareto_mask(ms, score).tolist() == expected


def test_front_line_is_the_best_score_within_each_time():
    rng = np.random.default_rng(1)
    ms, score = rng.uniform(1, 100, 20), rng.uniform(0, 1, 20)
    xs, ys = front_line(ms, score, x_max=200.0)
    assert xs[-1] == 200.0 and np.all(np.diff(xs) >= 0) and np.all(np.diff(ys) >= 0)
    for t in np.concatenate([ms, rng.uniform(ms.min(), 200, 20)]):
        step = ys[np.searchsorted(xs, t, side="right") - 1]  # value of the "post" step at t
        assert step == score[ms <= t].max()


def test_train_budgeted_stops_at_max_steps_and_is_seeded(tiny_dataset, tiny_run):
    run = tiny_run("handsnet", batch_size=8, epochs=5)
    train = load_data(tiny_dataset, run, with_test=False, progress=False).train
    a, info = train_budgeted(run, train, budget_s=600, max_steps=3)
    b, _ = train_budgeted(run, train, budget_s=600, max_steps=3)
    assert info["steps"] == 3 and info["images"] == 24
    assert info["epochs"] == pytest.approx(24 / (3 * len(train.y)))
    assert all(
        torch.equal(x, y)
        for x, y in zip(a.state_dict().values(), b.state_dict().values(), strict=True)
    )
    _, none = train_budgeted(run, train, budget_s=0.0, max_steps=3)
    assert none["steps"] == 0


def independent_accuracy(ckpt_path, dataset) -> tuple[float, torch.Tensor]:
    """Accuracy of a checkpoint in eval mode on the test split, read here one image at a time,
    and its logits (n_test, 2)."""
    model, run = model_from_checkpoint(load_checkpoint(ckpt_path))
    with DatasetReader(dataset) as ds:
        idx = ds.splits["test"]
        images = [net_input(ds.image[i], run.model.input_size, "classify") for i in idx]
        truth = ds.is_hand[:][idx]
    with torch.no_grad():
        logits = torch.cat([model(torch.from_numpy(x)[None, None]) for x in images])
    return float(np.mean(logits.argmax(1).numpy() == truth)), logits


@pytest.fixture(scope="module")
def pareto_run(tiny_dataset, checkpoints, tmp_path_factory):
    out = tmp_path_factory.mktemp("pareto")
    res = P.run_pareto(
        tiny_dataset,
        out,
        TINY,
        classifier=checkpoints["handsnet"],
        segmenter=checkpoints["segnet"],
        progress=False,
    )
    return out, res


def test_pareto_end_to_end(pareto_run, tiny_dataset, checkpoints, near_ties):
    out, res = pareto_run
    rows = {r["name"]: r for r in res["rows"]}
    with DatasetReader(tiny_dataset) as ds:
        h, w = ds.image.shape[1:]
        n_hand_test = int((ds.is_hand[:][ds.splits["test"]] == 1).sum())
    expected = {
        "HandsNet 32×48",
        "HandsNet 24×36",
        f"HandsNet {h}×{w}",
        "VGG16 w0.125 32×48",
        "BoVW (80 words)",
        "VGG16 w0.125 + SVM",
        "SegNet w0.125 32×48",
        "SegNet w0.125 24×36",
    }
    assert set(rows) == expected
    # the given classifier is used as is: its score is an independent evaluation's
    acc, logits = independent_accuracy(checkpoints["handsnet"], tiny_dataset)
    main = rows["HandsNet 32×48"]
    assert main["training"].startswith("given") and main["n_test"] == len(logits)
    near_ties.assert_rate(main["score"], acc, logits)
    # trained variants: 2 steps each, warm-started sizes from the given model, saved and valid
    small = load_checkpoint(out / "models" / "handsnet-24x36" / "best.pt")
    assert small["training"]["steps"] == 2
    assert small["budget"]["init"] == str(checkpoints["handsnet"])
    vgg = load_checkpoint(out / "models" / "vgg16-32x48-w0.125" / "best.pt")
    assert vgg["budget"]["init"] is None
    for r in res["rows"]:
        assert 0 <= r["score"] <= 1 and r["ms_fast"] > 0 and r["ms_eval"] > 0 and r["params"] > 0
        per_sample = 1 if r["task"] == "classify" else np.prod(r["size"])  # images or pixels
        images = len(logits) if r["task"] == "classify" else n_hand_test  # segmenters: hands only
        assert np.sum(r["cm"]) == images * per_sample
    # the front: every variant off it is dominated by one on it
    for task, names in res["front"].items():
        on = [rows[n] for n in names]
        for r in (r for r in res["rows"] if r["task"] == task and r["name"] not in names):
            assert any(f["ms_fast"] <= r["ms_fast"] and f["score"] >= r["score"] for f in on)


def test_pareto_report_and_charts(pareto_run):
    out, _ = pareto_run
    text = (out / "report.md").read_text()
    for needle in (
        "## Classification",
        "## Segmentation",
        "| HandsNet 24×36 |",
        "97.81",
        "89.17",
        "HandsNet (paper)",
        "unknown",
        "Seed: 0",
    ):
        assert needle in text, needle
    for png in ("pareto_classification.png", "pareto_segmentation.png"):
        img = imread(out / png)[..., :3]
        assert img.std() > 0.05 and (img.mean(-1) < 0.5).mean() > 0.005  # drawn, not blank
    assert (out / "results.json").is_file()


def test_pareto_rerun_reuses_trained_variants(pareto_run, tiny_dataset, checkpoints, capsys):
    out, _ = pareto_run
    path = out / "models" / "handsnet-24x36" / "best.pt"
    before = path.stat().st_mtime_ns
    settings = P.ParetoSettings(
        **{
            **TINY.__dict__,
            "classic": False,
            "segmentation": False,
            "sizes": ("24x36",),
            "widths": (),
        }
    )
    res = P.run_pareto(
        tiny_dataset,
        out / "again",
        settings,
        classifier=checkpoints["handsnet"],
        models_dir=out / "models",
        progress=False,
    )
    assert f"reusing {path}" in capsys.readouterr().out and path.stat().st_mtime_ns == before
    assert [r["name"] for r in res["rows"]] == ["HandsNet 32×48", "HandsNet 24×36"]


@pytest.fixture(scope="module")
def app() -> typer.Typer:
    root = typer.Typer()
    register(root)
    return root


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["{missing}"], "DATASET {missing}: no dataset there"),
        (["--sizes", "34by50"], "expected <height>x<width>"),
        (["--sizes", "12x12"], "too small"),
        (["--widths", "0"], "widths must lie in"),
        (["--widths", "a,b"], "comma-separated"),
        (["--classifier", "{missing}.pt"], "no checkpoint"),
        (["--classifier", "{segnet}"], "--classifier {segnet} holds a segnet network"),
        (["--budget-min", "0"], "--budget-min 0.0 is out of range"),
        (["--segmenter", "{segnet}", "--no-segmentation"], "--segmenter with --no-segmentation"),
    ],
)
def test_bad_input_fails_before_work(app, tiny_dataset, checkpoints, tmp_path, args, message):
    out = tmp_path / "out"
    names = {"missing": str(tmp_path / "missing"), "segnet": str(checkpoints["segnet"])}
    args = [a.format(**names) for a in args]
    data = [] if args[0] == names["missing"] else [str(tiny_dataset)]
    base = ["experiment", "pareto", *data, "--out", str(out), "--quick", "--no-progress"]
    res = CliRunner().invoke(app, base + args)
    assert res.exit_code == 2, res.output
    assert "error:" in res.output and message.format(**names) in res.output, res.output
    assert not out.exists()
