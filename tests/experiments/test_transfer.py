"""`handskin experiment transfer` (Test C) end to end on tiny generated datasets: the curve's
subsets are nested, class-balanced and subject-/instance-disjoint from the test split (checked on
the dataset's own ids), the zero-shot score equals an independent evaluation, the synthetic
pretraining set leaves out the target's test instances, datasets are reused, and bad input fails
before any work."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
import typer
from matplotlib.image import imread
from typer.testing import CliRunner

from experiments import transfer as T
from experiments import transfer_runs as R
from experiments.cli import register
from experiments.transfer_runs import nested_order
from learn.inputs import input_canvas
from learn.train.checkpoint import load_checkpoint, model_from_checkpoint
from tactile.dataset.reader import DatasetReader
from tactile.errors import ConfigError
from tactile.images.resize import resize_grey

SETTINGS = T.TransferSettings(
    curve_sizes=(4, 8),
    finetune_epochs=2,
    pretrain_epochs=2,
    pretrain_flips=False,
    input_size=(32, 48),
    seed=1,
    threads=1,
)
PLAN = T.DataPlan(n_target=40, n_pretrain=24, tiny=True)


def test_nested_order_prefixes_are_class_balanced():
    labels = (np.random.default_rng(0).random(50) < 0.3).astype(int)
    order = nested_order(labels, seed=3)
    assert sorted(order) == list(range(50))
    share = np.bincount(labels) / len(labels)
    for n in range(1, 51):
        counts = np.bincount(labels[order[:n]], minlength=2)
        assert np.all(np.abs(counts - n * share) <= 1), (n, counts)
    assert np.array_equal(order, nested_order(labels, 3))
    assert not np.array_equal(order, nested_order(labels, 4))


def test_dataset_seeds_differ_by_role_and_follow_the_seed():
    seeds = [T.dataset_seed(0, role) for role in T.ROLES]
    assert len(set(seeds)) == 3 and seeds == [T.dataset_seed(0, r) for r in T.ROLES]
    assert T.dataset_seed(1, "target") != T.dataset_seed(0, "target")


@pytest.fixture(scope="module")
def source(tmp_path_factory):
    """A tiny forearm dataset: the source part."""
    from sim.generate.run import generate

    folder = tmp_path_factory.mktemp("source") / "forearm"
    cfg = T.generate_config("forearm", 24, T.dataset_seed(SETTINGS.seed, "source"), tiny=True)
    generate(cfg, folder, workers=1, progress=False)
    return folder


@pytest.fixture(scope="module")
def transfer_run(source, tmp_path_factory):
    torch.set_num_threads(1)
    out = tmp_path_factory.mktemp("transfer")
    return out, T.run_transfer_experiment(source, out, s=SETTINGS, plan=PLAN, progress=False)


def again(source, out, folder, **kw) -> dict:
    """The experiment into ``folder`` on the datasets the first run generated in ``out``."""
    target, datasets = out / "data" / "end_effector", out / "data"
    kw = {"s": SETTINGS, "plan": PLAN, "progress": False} | kw
    return T.run_transfer_experiment(source, folder, target=target, datasets=datasets, **kw)


def ids(folder, index: np.ndarray) -> tuple[set, set]:
    """(subject ids >= 0, instance ids >= 0) of the samples ``index`` of a dataset."""
    with DatasetReader(folder) as ds:
        subject, instance = ds.subject_id[:][index], ds.instance_id[:][index]
    return set(subject[subject >= 0].tolist()), set(instance[instance >= 0].tolist())


def test_curve_subsets_are_nested_balanced_and_disjoint_from_test(transfer_run):
    out, res = transfer_run
    target = out / "data" / "end_effector"
    with DatasetReader(target) as ds:
        train, test, hand = ds.splits["train"], ds.splits["test"], ds.is_hand[:]
        assert ds.attrs["part"] == "end_effector"
    r = res["classify"]
    assert (r["n_train"], r["n_test"]) == (len(train), len(test))
    test_subjects, test_instances = ids(target, test)
    assert test_subjects and test_instances  # the disjointness below is not vacuous
    previous: set = set()
    for k, n in enumerate([4, 8, len(train)]):
        samples = {tuple(r["curve"][i][k]["samples"]) for i in r["curve"]}
        assert len(samples) == 1  # the three starting points train on the same samples
        chosen = np.array(samples.pop())
        assert len(chosen) == n and set(chosen) <= set(train) and previous <= set(chosen)
        subjects, instances = ids(target, chosen)
        assert not subjects & test_subjects and not instances & test_instances
        share = hand[train].mean()
        assert abs(hand[chosen].sum() - n * share) <= 1
        previous = set(chosen)
    assert r["finetuned"]["samples"] == sorted(train.tolist())


def test_zero_shot_equals_an_independent_evaluation(transfer_run, near_ties):
    out, res = transfer_run
    r = res["classify"]
    model, run = model_from_checkpoint(load_checkpoint(r["forearm_checkpoint"]))
    with DatasetReader(out / "data" / "end_effector") as ds:
        test = ds.splits["test"]
        x = np.stack([resize_grey(ds.image[i], run.model.input_size) for i in test])
        truth = ds.is_hand[:][test]
    with torch.no_grad():
        logits = model(torch.from_numpy(x)[:, None])
    right = np.mean(logits.argmax(1).numpy() == truth)
    near_ties.assert_rate(r["zero_shot"]["forearm"]["metrics"]["accuracy"], right, logits)
    cm = np.array(r["zero_shot"]["forearm"]["cm"])
    assert cm.sum() == len(test) and np.array_equal(cm.sum(1), np.bincount(truth, minlength=2))


def test_synthetic_pretraining_leaves_out_the_target_test_instances(transfer_run):
    out, res = transfer_run
    ckpt = load_checkpoint(res["classify"]["synthetic_checkpoint"])
    with DatasetReader(out / "data" / "end_effector") as ds:
        held = ds.instance_id[:][ds.splits["test"]]
    with DatasetReader(out / "data" / "end_effector_synthetic") as ds:
        n, instance = len(ds), ds.instance_id[:]
    dropped = int(np.isin(instance, held[held >= 0]).sum())
    desc = ckpt["data"]
    assert desc["n_dropped_shared_instances"] == dropped
    assert desc["n_train"] + desc["n_val"] == n - dropped


def test_transfer_report_and_chart(transfer_run):
    out, res = transfer_run
    text = (out / "report.md").read_text()
    for needle in (
        "(paper: Table 15)",
        "(paper: Table 16)",
        "learning curve",
        "unknown",
        "true \\ predicted",
        "end_effector_synthetic",
        "halved after 1 of 2",
    ):
        assert needle in text, needle
    img = imread(out / "curve_classify.png")[..., :3]
    assert img.std() > 0.05 and (img.mean(-1) < 0.5).mean() > 0.005
    assert res["report"] == str(out / "report.md") and (out / "results.json").is_file()


def test_a_rerun_reads_every_finetuning_result_back_without_training(
    source, transfer_run, monkeypatch
):
    """Stopped runs resume: each fine-tuning result is on disk with its key, so a rerun of the
    same command trains nothing and reports the same numbers."""
    import learn.train.runs

    out, res = transfer_run
    files = sorted((out / "models" / "finetune").glob("classify-*.json"))
    assert len(files) == 3 * 3  # 3 starts x (4, 8, all); forearm/all is the Test C run itself

    def no_training(*args, **kwargs):
        raise AssertionError("a rerun must not train")

    monkeypatch.setattr(learn.train.runs, "fit", no_training)
    monkeypatch.setattr(R, "fit", no_training)
    rerun = T.run_transfer_experiment(source, out, s=SETTINGS, plan=PLAN, progress=False)
    assert rerun["classify"]["curve"] == res["classify"]["curve"]
    assert rerun["classify"]["finetuned"] == res["classify"]["finetuned"]


def test_segmentation_alone(source, transfer_run, tmp_path):
    """--no-classification --segmentation trains and reports SegNet only, on the same datasets
    (the target given as a folder); every fine-tuning result is a segmentation one (3 starts x
    (4, 8, all))."""
    out, _ = transfer_run
    data = {
        "target": out / "data" / "end_effector",
        "pretrain": out / "data" / "end_effector_synthetic",
    }
    s = dataclasses.replace(SETTINGS, classification=False, segmentation=True)
    res = again(source, out, tmp_path, s=s)
    assert set(res) == {"segment", "report"}
    files = sorted(p.name for p in (tmp_path / "models" / "finetune").glob("*.json"))
    assert len(files) == 9 and all(f.startswith("segment-") for f in files), files
    text = (tmp_path / "report.md").read_text()
    assert "Segmentation: zero-shot" in text and "Classification" not in text
    assert (tmp_path / "curve_segment.png").is_file() and not (tmp_path / "data").exists()
    with DatasetReader(data["target"]) as ds:
        held = ds.instance_id[:][ds.splits["test"]]
    with DatasetReader(data["pretrain"]) as ds:  # SegNet pretrains on the hand samples only
        hands = ds.is_hand[:].astype(bool) & ~np.isin(ds.instance_id[:], held[held >= 0])
    desc = load_checkpoint(res["segment"]["synthetic_checkpoint"])["data"]
    assert desc["n_train"] + desc["n_val"] == hands.sum() > 0
    for points in res["segment"]["curve"].values():
        assert [p["n"] for p in points][:2] == [4, 8] and len(points) == 3
        assert all(0 <= p["metrics"]["mean_iou"] <= 1 for p in points), points


def test_keep_scale_feeds_the_forearm_model_images_centred_at_the_forearm_scale(
    source, transfer_run, tmp_path, monkeypatch, near_ties
):
    """--keep-scale adds "forearm at scale" rows: the forearm model is scored on end-effector
    images zero-padded by hand to the forearm map's size (mm) before the resize (the very
    tensor, and its score), it fine-tunes on the same subsets as the other starts, and the
    report says so."""
    out, res = transfer_run
    data = {"source": source, "target": out / "data" / "end_effector"}
    ckpt = res["classify"]["forearm_checkpoint"]
    s = dataclasses.replace(SETTINGS, keep_scale=True)
    scored, score = [], R.score
    monkeypatch.setattr(R, "score", lambda m, test, n: scored.append(test.x) or score(m, test, n))
    got = again(source, out, tmp_path, s=s, classifier=ckpt)["classify"]
    model, run = model_from_checkpoint(load_checkpoint(ckpt))
    with DatasetReader(data["source"]) as ds:
        canvas_mm = [float(n * ds.map.step_mm) for n in ds.map.shape]
    with DatasetReader(data["target"]) as ds:
        canvas = input_canvas(canvas_mm, ds.map.step_mm)  # the source's mm on the target's grid
        test = ds.splits["test"]
        image = ds.image[np.sort(test)][np.argsort(np.argsort(test))]
        truth = ds.is_hand[:][test]
    h, w = image.shape[1:]
    top, left = (canvas[0] - h) // 2, (canvas[1] - w) // 2
    assert top > 0 and left > 0  # the end-effector map is the smaller one: padding, no crop
    padded = np.pad(image, ((0, 0), (top, canvas[0] - h - top), (left, canvas[1] - w - left)))
    x = torch.from_numpy(resize_grey(padded, run.model.input_size))[:, None]
    assert any(torch.equal(t, x) for t in scored)
    assert not torch.allclose(scored[0], x, atol=1e-3)  # the stretched inputs differ
    with torch.no_grad():
        logits = model(x)
    zero = got["zero_shot"]["forearm at scale"]["metrics"]["accuracy"]
    near_ties.assert_rate(zero, np.mean(logits.argmax(1).numpy() == truth), logits)
    assert got["canvas_mm"] == canvas_mm
    assert list(got["curve"]) == ["scratch", "forearm", "synthetic EE", "forearm at scale"]
    for k in range(3):
        assert len({tuple(got["curve"][i][k]["samples"]) for i in got["curve"]}) == 1
    assert got["curve"]["forearm"] == res["classify"]["curve"]["forearm"]  # unchanged rows
    text = (tmp_path / "report.md").read_text()
    assert "source model at its scale (canvas)" in text and "from forearm at scale %" in text
    assert f"{canvas_mm[0]:g} × {canvas_mm[1]:g} mm canvas" in text


def test_keep_scale_refuses_a_model_that_already_has_a_canvas(transfer_run, tmp_path):
    _, res = transfer_run
    ckpt = load_checkpoint(res["classify"]["forearm_checkpoint"])
    ckpt["config"]["model"]["canvas_mm"] = [229.0, 383.0]
    torch.save(ckpt, tmp_path / "canvas.pt")
    s = dataclasses.replace(SETTINGS, keep_scale=True)
    with pytest.raises(ConfigError, match=r"already centres its inputs.*drop --keep-scale"):
        R.model_config("classify", tmp_path / "canvas.pt", s)
    assert R.model_config("classify", tmp_path / "canvas.pt", SETTINGS).canvas_mm == (229, 383)


def test_a_cached_result_is_recomputed_when_its_key_differs(tmp_path):
    cached, calls = R.cached, []
    path = tmp_path / "r.json"
    assert cached(path, {"a": 1}, lambda: calls.append(1) or {"x": 1.5}) == {"x": 1.5}
    assert cached(path, {"a": 1}, lambda: calls.append(2) or {"x": 9.0}) == {"x": 1.5}
    assert cached(path, {"a": 2}, lambda: calls.append(3) or {"x": 2.5}) == {"x": 2.5}
    assert calls == [1, 3]
    path.write_text("{not json")  # a torn file is recomputed, not an error
    assert cached(path, {"a": 2}, lambda: {"x": 4.0}) == {"x": 4.0}


def test_datasets_are_reused_and_a_folder_of_another_size_refused(transfer_run):
    out, _ = transfer_run
    folder = out / "data" / "end_effector"
    before = (folder / "dataset.h5").stat().st_mtime_ns
    seed = T.dataset_seed(SETTINGS.seed, "target")
    cfg = T.generate_config("end_effector", PLAN.n_target, seed, tiny=True)
    assert T.ensure_dataset(folder, cfg, 1, progress=False) == folder
    assert (folder / "dataset.h5").stat().st_mtime_ns == before
    bigger = T.generate_config("end_effector", 50, seed, tiny=True)
    with pytest.raises(ConfigError, match="holds 40"):
        T.ensure_dataset(folder, bigger, 1, progress=False)


@pytest.fixture(scope="module")
def app() -> typer.Typer:
    root = typer.Typer()
    register(root)
    return root


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--classifier", "{missing}"], "no checkpoint"),
        (["--segmenter", "{classifier}"], "holds a handsnet network; give one of segnet, fcn16s"),
        (["--curve", "10,x"], "give comma-separated values"),
        (["--epochs", "0"], "--epochs 0 is out of range"),
        (["--no-classification"], "neither classification nor segmentation"),
        (["--precision", "fp16"], "--precision 'fp16'"),
        (
            ["--no-classification", "--segmentation", "--classifier", "{classifier}"],
            "--classifier with --no-classification",
        ),
        (["--workers", "0"], "--workers 0 is out of range"),
    ],
)
def test_bad_input_fails_before_work(app, source, transfer_run, tmp_path, args, message):
    _, res = transfer_run
    out = tmp_path / "out"
    names = {
        "missing": str(tmp_path / "missing.pt"),
        "classifier": res["classify"]["forearm_checkpoint"],
    }
    args = [a.format(**names) for a in args]
    base = ["experiment", "transfer", str(source), "--out", str(out), "--quick", "--no-progress"]
    result = CliRunner().invoke(app, base + args)
    assert result.exit_code == 2, result.output
    assert "error:" in result.output and message in " ".join(result.output.split()), result.output
    assert not out.exists()


def test_segmentation_tables_follow_table_15_layout():
    from experiments.report import SEG_LABELS
    from learn.train.validation import scores

    cm = np.random.default_rng(2).integers(0, 50, (7, 7))
    table = T.scores_table("segment", [("SegNet", {"metrics": scores(cm)})])
    head, _, row = table.splitlines()
    assert head.split(" | ")[1:5] == [f"{h} % (ours)" for h in SEG_LABELS.values()]
    cells = row.strip("| ").split(" | ")
    ours = [f"{100 * scores(cm)[k]:.2f}" for k in SEG_LABELS]
    assert cells[1:5] == ours and cells[5:] == ["unknown"] * 4
