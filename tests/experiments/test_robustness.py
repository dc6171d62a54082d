"""robustness-a / robustness-b: regenerated images, corrupted maps, the studies and the reports.

``sensed_dataset`` rewrites the tiny dataset as the generator writes a real one: raw counts with
a per-taxel baseline, drift and read noise, and images made from the sensed pressure (3-sigma
floor), computed here independently of the code under test.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch
import typer
from matplotlib.image import imread
from typer.testing import CliRunner

from experiments import studies as E
from experiments.cli import register
from experiments.frames import KEY_SPOTS, images, load_frames, net_inputs, stream
from experiments.maps import IGNORE, discarded_hand_pixels, rebuild, spot_pattern, warp_labels
from experiments.networks import BATCH, Predictor, plan_run
from experiments.robustness import run_robustness_a, run_robustness_b
from experiments.settings import QUICK_PLAN, Scale, TrainPlan
from learn import metrics as M
from learn.data.dataset import TorchTactileDataset
from learn.data.load import load_data, materialize
from learn.train.checkpoint import load_checkpoint, model_from_checkpoint
from learn.train.validation import evaluate_tensors, logits_of
from tactile import TactileMap
from tactile.dataset import DatasetWriter, open_dataset
from tactile.images.faults import blind_spots, nested_removal, zero_taxels
from tactile.images.labels import label_image
from tactile.images.resize import resize_labels

GAIN, NOISE, BASE = 2.0, 4.0, 100.0  # counts/Pa, counts (sd), counts


@pytest.fixture(scope="module")
def sensed_dataset(tiny_dataset, tmp_path_factory):
    """The tiny dataset re-recorded with baseline, drift, noise and the 3-sigma floor."""
    src = open_dataset(tiny_dataset)
    tmap, layout = src.map, src.layout
    n = layout.n_taxels
    rng = np.random.default_rng(11)
    base, drift = rng.normal(BASE, 10.0, n), rng.normal(0.0, 3.0, n)
    samples = []
    for i in range(len(src)):
        s = src[i]
        t = float(np.float32(rng.uniform(0.1, 1.5)))  # stored as float32: the readout sees it
        counts = base + drift * t + GAIN * s["pressure_pa"] + rng.normal(0, NOISE, n)
        raw = np.clip(np.rint(counts), 0, 65535).astype(np.uint16)
        signal = raw - base - drift * t
        p = np.where(signal > 3 * NOISE, signal, 0.0) / GAIN
        hand = bool(s["is_hand"])
        samples.append(
            {
                "raw": raw,
                "pressure_pa": s["pressure_pa"],
                "taxel_label": s["taxel_label"],
                "image": tmap.image(p),
                "is_hand": s["is_hand"],
                "time_s": np.float32(t),
                "label_image": tmap.label_image(p, s["taxel_label"])
                if hand
                else np.zeros(tmap.shape, np.uint8),
                "subject_id": s["subject_id"],
                "instance_id": s["instance_id"],
            }
        )
    folder = tmp_path_factory.mktemp("robust") / "sensed"
    writer = DatasetWriter(
        folder,
        config={"episode": {"skin": {"noise_std_counts": NOISE}}},
        part="sector",
        generator_version="t",
        seed=3,
        tmap=tmap,
        layout=layout,
        attrs={
            "skin_counts_per_pa": GAIN,
            "skin_baseline_counts": base,
            "skin_drift_counts_per_s": drift,
        },
    )
    writer.write_chunk(0, samples)
    writer.merge()
    return folder


@pytest.fixture(scope="module")
def predictors(checkpoints):
    """The eval-mode networks (predictions exactly those of learn.evaluate)."""
    return [
        Predictor.load("HandsNet", checkpoints["handsnet"], fast=False),
        Predictor.load("SegNet", checkpoints["segnet"], fast=False),
    ]


def all_frames(path):
    return load_frames(path, "test", n_classify=None, n_segment=10_000, seed=0)


def test_readout_reproduces_the_stored_images(sensed_dataset):
    frames = all_frames(sensed_dataset)
    ds = open_dataset(sensed_dataset)
    stored = np.stack([ds.image[i] for i in frames.sample_ids])
    assert np.array_equal(images(frames.tmap, frames.pressure_pa), stored)
    stored_labels = np.stack([ds.label_image[i] for i in frames.sample_ids[frames.segment]])
    assert np.array_equal(frames.label_image, stored_labels)
    assert (frames.is_hand[frames.segment] == 1).all()


def test_subsets_are_seeded_and_sized(sensed_dataset):
    a = load_frames(sensed_dataset, "test", n_classify=5, n_segment=3, seed=4)
    b = load_frames(sensed_dataset, "test", n_classify=5, n_segment=3, seed=4)
    assert len(a.classify) == 5 and len(a.segment) == 3
    assert np.array_equal(a.sample_ids, b.sample_ids)
    test_ids = open_dataset(sensed_dataset).splits["test"]
    assert set(a.sample_ids) <= set(test_ids)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_spot_pattern_is_tactile_faults_blind_spots(sensed_dataset, seed):
    tmap = open_dataset(sensed_dataset).map
    blind, pixels = spot_pattern(tmap, 2, 12.0, np.random.default_rng(seed))
    assert np.array_equal(blind, blind_spots(tmap, 2, 12.0, np.random.default_rng(seed)))
    centres = tmap.pixel_centers()
    uv = tmap.uv[blind]
    near_blind = (((centres[:, :, None, :] - uv) ** 2).sum(-1) <= 12.0**2).any(-1)
    assert pixels.any() and not (pixels & ~near_blind).any()  # spot pixels near a blind taxel


def test_rebuild_keeping_every_taxel_is_the_identity(sensed_dataset):
    ds = open_dataset(sensed_dataset)
    removed = rebuild(ds.map, ds.layout, np.arange(ds.map.n_taxels), 0.0)
    labels = ds.label_image[:]
    warped = warp_labels(labels, removed)
    cover = ds.map.coverage()
    assert np.array_equal(warped[:, cover], labels[:, cover])
    assert (warped[:, ~cover] == IGNORE).all()
    assert discarded_hand_pixels(labels, removed)[0] == 0
    again = TactileMap.build(ds.layout, step_mm=ds.map.step_mm)  # maps rebuild as made
    assert again.shape == ds.map.shape and np.array_equal(again.faces, ds.map.faces)


def test_trace_back_agrees_with_a_similarity_fit(sensed_dataset):
    """The rebuilt map of a developable lattice is a rotation + shift of the full one: the
    piecewise trace-back must land where the global least-squares similarity puts pixels."""
    ds = open_dataset(sensed_dataset)
    full = ds.map
    keep = nested_removal(full.n_taxels, [0.3], np.random.default_rng(5))[0]
    removed = rebuild(full, ds.layout, keep, 0.3)
    a, b = removed.tmap.uv, full.uv[keep]
    ok = np.isfinite(a).all(1) & np.isfinite(b).all(1)
    design = np.c_[a[ok], np.ones(ok.sum())]
    coef = np.linalg.lstsq(design, b[ok], rcond=None)[0]
    centres = removed.tmap.pixel_centers().reshape(-1, 2)
    uv = np.c_[centres, np.ones(len(centres))] @ coef
    col = np.floor((uv[:, 0] - full.origin_mm[0]) / full.step_mm).astype(int)
    row = np.floor((full.origin_mm[1] - uv[:, 1]) / full.step_mm).astype(int)
    valid = removed.source >= 0
    assert valid.mean() > 0.5
    r0, c0 = np.divmod(removed.source[valid], full.shape[1])
    close = (np.abs(r0 - row[valid]) <= 1) & (np.abs(c0 - col[valid]) <= 1)
    assert close.mean() > 0.97
    assert removed.covered.sum() <= full.coverage().sum()


def scores_of(predictor: Predictor, x: np.ndarray) -> np.ndarray:
    """The scores ``predictor.predict(x)`` takes its argmax of, unpressed pixels of a segmenter
    made clear background (`learn.inputs.unpressed_as_background`)."""
    scores = logits_of(predictor.net, torch.from_numpy(x), BATCH).numpy()
    return scores if predictor.task == "classify" else np.where(x > 0, scores, BACKGROUND)


BACKGROUND = np.eye(7)[0][:, None, None]  # class 0 certain, as scores (7, 1, 1)


def test_zero_corruption_equals_the_plain_evaluation(
    sensed_dataset, predictors, checkpoints, near_ties
):
    """Equal but at near ties: the plain evaluation batches the rows otherwise."""
    frames = all_frames(sensed_dataset)
    _, cms = E.zero_corruption(frames, predictors)
    model, run = model_from_checkpoint(load_checkpoint(checkpoints["handsnet"]))
    test = load_data(sensed_dataset, run, progress=False).test
    plain = evaluate_tensors(model, test, 2)
    near_ties.assert_cm(cms["HandsNet"], plain.cm, scores_of(predictors[0], test.x.numpy()))
    seg, seg_run = model_from_checkpoint(load_checkpoint(checkpoints["segnet"]))
    ds = TorchTactileDataset(sensed_dataset, "test", "segment", seg_run.model.input_size, False)
    ds.indices = frames.sample_ids[frames.segment]
    seg_test = materialize(ds, progress=False)
    plain_seg = evaluate_tensors(seg, seg_test, 7)
    near_ties.assert_cm(cms["SegNet"], plain_seg.cm, scores_of(predictors[1], seg_test.x.numpy()))


def slow_blind_spot_cms(frames, predictors, blind, blind_px):
    """Reference: every row re-imaged, every network run on every row, truth recomputed; with
    the scores of each network's decisions."""
    p = zero_taxels(frames.pressure_pa, blind)
    imgs = images(frames.tmap, p)
    clf, seg = predictors
    x_c = net_inputs(imgs[frames.classify], clf.size, "classify")
    cm_c = M.confusion_matrix(frames.is_hand[frames.classify], clf.predict(x_c), 2)
    truth = np.stack(
        [label_image(frames.tmap, p[r], frames.taxel_label[r]) for r in frames.segment]
    )
    truth[:, blind_px] = 0
    x_s = net_inputs(imgs[frames.segment], seg.size, "segment")
    cm_s = M.confusion_matrix(resize_labels(truth, seg.size), seg.predict(x_s), 7)
    cms = {"HandsNet": cm_c.tolist(), "SegNet": cm_s.tolist()}
    return cms, {"HandsNet": scores_of(clf, x_c), "SegNet": scores_of(seg, x_s)}


def test_blind_spot_shortcut_equals_recomputing_everything(sensed_dataset, predictors, near_ties):
    """Equal but at near ties: the shortcut runs only the rows a pattern changes."""
    frames = all_frames(sensed_dataset)
    study = E.blind_spot_study(frames, predictors, [(2, 15.0), (1, 30.0)], 2, seed=7)
    for cond in study["conditions"]:
        assert 0 < max(cond["affected"]) and min(cond["affected"]) < 1
        for k in range(2):
            rng = stream(7, KEY_SPOTS, cond["n_spots"], round(cond["radius_mm"] * 1000), k)
            blind, px = spot_pattern(frames.tmap, cond["n_spots"], cond["radius_mm"], rng)
            ref, scores = slow_blind_spot_cms(frames, predictors, blind, px)
            for net in ("HandsNet", "SegNet"):
                near_ties.assert_cm(cond["cm"][net][k], ref[net], scores[net])


def test_removal_study_zero_row_and_nesting(sensed_dataset, predictors):
    frames = all_frames(sensed_dataset)
    study = E.removal_study(frames, predictors, [0.0, 0.3, 0.6], n_patterns=2, seed=3)
    zero, mid, high = study["conditions"]
    _, base = E.zero_corruption(frames, predictors)
    assert zero["cm"]["HandsNet"] == [base["HandsNet"]] * 2
    assert zero["discarded_px"] == [0, 0]
    seg = predictors[1]
    truth = frames.label_image.copy()
    truth[:, ~frames.tmap.coverage()] = IGNORE
    out = E.run_rows(
        frames.tmap,
        frames.pressure_pa[frames.segment],
        np.zeros(len(frames.segment), bool),
        np.ones(len(frames.segment), bool),
        predictors,
    )
    cm = M.confusion_matrix(resize_labels(truth, seg.size), out[0]["SegNet"], 7, IGNORE)
    assert zero["cm"]["SegNet"][0] == cm.tolist()
    n = frames.tmap.n_taxels
    assert zero["n_kept"] == [n, n]
    assert all(a > b for a, b in zip(mid["n_kept"], high["n_kept"], strict=True))
    assert high["n_kept"][0] == n - round(0.6 * n)
    total = np.asarray(high["cm"]["HandsNet"]).sum(axis=(1, 2))
    assert (total == len(frames.classify)).all()


def test_plans_change_only_what_they_say():
    from learn import config as C

    clf, seg = plan_run("handsnet", QUICK_PLAN, 4), plan_run("segnet", QUICK_PLAN, 4)
    assert clf.train == dataclasses.replace(C.HANDSNET.train, epochs=2, seed=4)
    assert seg.train == dataclasses.replace(C.SEGNET.train, epochs=2, seed=4)
    assert (clf.model, seg.model) == (C.HANDSNET.model, C.SEGNET.model) and clf.flips
    assert QUICK_PLAN.samples("handsnet") is None and QUICK_PLAN.samples("segnet") == 600
    tiny = plan_run("segnet", TrainPlan(seg_width=0.125, input_size=(32, 48), flips=False), 0)
    assert (tiny.model.width, tiny.model.input_size, tiny.flips) == (0.125, (32, 48), False)


def tiny_scale(**kw) -> Scale:
    base = {
        "n_patterns": 1,
        "n_classify": None,
        "n_segment": 4,
        "n_spots": (1, 3),
        "radii_mm": (10.0, 20.0),
        "fractions": (0.0, 0.5),
    }
    return Scale(**{**base, **kw})


def chart_is_drawn(path) -> bool:
    img = imread(path)
    return img.ndim == 3 and img[..., :3].std() > 0.02


def test_robustness_a_end_to_end(sensed_dataset, checkpoints, tmp_path):
    report = run_robustness_a(
        sensed_dataset,
        tmp_path,
        scale=tiny_scale(),
        seed=1,
        classifier=checkpoints["handsnet"],
        segmenter=checkpoints["segnet"],
        threads=1,
        progress=False,
    )
    text = report.read_text()
    assert "Table 11" in text and "Table 12" in text and "| N_s \\ r | 10 mm | 20 mm |" in text
    for png in ("heatmap_classification.png", "heatmap_segmentation.png"):
        assert chart_is_drawn(tmp_path / png)
    res = json.loads((tmp_path / "results.json").read_text())["results"]
    conds = res["study"]["conditions"]
    assert [(c["n_spots"], c["radius_mm"]) for c in conds] == [(1, 10), (1, 20), (3, 10), (3, 20)]


def test_robustness_b_end_to_end_trains_missing_networks(sensed_dataset, tmp_path, capsys):
    plan = TrainPlan(
        epochs=1,
        n_train=8,
        seg_n_train=8,
        flips=False,
        seg_width=0.125,
        input_size=(32, 48),
        suffix="_tiny",
    )
    scale = tiny_scale(plan=plan, n_classify=6)
    report = run_robustness_b(
        sensed_dataset, tmp_path, scale=scale, seed=2, threads=1, progress=False
    )
    text = report.read_text()
    assert "Table 13" in text and "Table 14" in text and "unknown" in text
    assert "97.81" in text  # the paper's intact-skin accuracy (Table 3) on the 0 % row
    for png in ("removal_classification.png", "removal_segmentation.png"):
        assert chart_is_drawn(tmp_path / png)
    stamp = (tmp_path / "models" / "handsnet_tiny" / "best.pt").stat().st_mtime
    run_robustness_b(
        sensed_dataset,
        tmp_path / "again",
        scale=scale,
        seed=2,
        models_dir=tmp_path / "models",
        threads=1,
        progress=False,
    )
    assert "reusing" in capsys.readouterr().out
    assert (tmp_path / "models" / "handsnet_tiny" / "best.pt").stat().st_mtime == stamp
    res = json.loads((tmp_path / "results.json").read_text())["results"]
    assert len(res["study"]["conditions"][0]["cm"]["HandsNet"][0]) == 2


def test_without_segmentation_only_the_classifier_is_run(sensed_dataset, checkpoints, tmp_path):
    scale = tiny_scale(n_segment=0)
    report = run_robustness_b(
        sensed_dataset, tmp_path, scale, 1, classifier=checkpoints["handsnet"], progress=False
    )
    text = report.read_text()
    assert "Table 13" in text and "Table 14" not in text and "SegNet" not in text
    assert not (tmp_path / "removal_segmentation.png").exists()
    res = json.loads((tmp_path / "results.json").read_text())["results"]
    assert list(res["study"]["conditions"][1]["cm"]) == ["HandsNet"]


def invoke(*args: str):
    """`handskin experiment ARGS` on the experiments' app alone."""
    root = typer.Typer()
    register(root)
    return CliRunner().invoke(root, ["experiment", *args])


def test_cli_errors_name_the_problem(tmp_path):
    res = invoke("robustness-a", str(tmp_path / "missing"), "--out", str(tmp_path / "o"))
    assert res.exit_code == 2 and "DATASET" in res.output and "no dataset there" in res.output
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--classifier", "{segnet}"], "--classifier {segnet} holds a segnet network"),
        (["--segmenter", "{segnet}", "--no-segmentation"], "--segmenter with --no-segmentation"),
        (["--patterns", "0"], "--patterns 0 is out of range"),
        (["--threads", "0"], "--threads 0 is out of range"),
    ],
)
def test_cli_refuses_bad_options_before_any_work(
    tmp_path, checkpoints, sensed_dataset, args, message
):
    names = {"segnet": str(checkpoints["segnet"])}
    out = tmp_path / "o"
    res = invoke(
        "robustness-b", str(sensed_dataset), "--out", str(out), *(a.format(**names) for a in args)
    )
    assert res.exit_code == 2 and message.format(**names) in " ".join(res.output.split()), (
        res.output
    )
    assert not out.exists()


def test_zero_corruption_keeps_a_models_canvas(sensed_dataset, checkpoints, tmp_path):
    """A network with an input canvas (`ModelConfig.canvas_mm`) sees the same inputs in the
    robustness tests as in `handskin evaluate`: its zero-corruption confusion matrices equal the
    plain evaluation's on inputs made through `learn.data` (a canvas wider than the map and
    shorter than it, so both padding and cropping happen)."""
    canvas = [40.0, 120.0]
    paths = {}
    for arch in ("handsnet", "segnet"):
        ckpt = load_checkpoint(checkpoints[arch])
        model = dict(ckpt["config"]["model"], canvas_mm=canvas)
        paths[arch] = tmp_path / f"{arch}.pt"
        torch.save(dict(ckpt, config=dict(ckpt["config"], model=model)), paths[arch])
    preds = [
        Predictor.load("HandsNet", paths["handsnet"], fast=False),
        Predictor.load("SegNet", paths["segnet"], fast=False),
    ]
    frames = all_frames(sensed_dataset)
    assert frames.tmap.shape[0] > canvas[0] and frames.tmap.shape[1] < canvas[1]
    _, cms = E.zero_corruption(frames, preds)
    model, run = model_from_checkpoint(load_checkpoint(paths["handsnet"]))
    assert run.model.canvas_mm == tuple(canvas)
    plain = evaluate_tensors(model, load_data(sensed_dataset, run, progress=False).test, 2)
    assert cms["HandsNet"] == plain.cm.tolist()
    seg, seg_run = model_from_checkpoint(load_checkpoint(paths["segnet"]))
    ds = TorchTactileDataset(
        sensed_dataset,
        "test",
        "segment",
        seg_run.model.input_size,
        False,
        canvas_mm=seg_run.model.canvas_mm,
    )
    ds.indices = frames.sample_ids[frames.segment]
    plain_seg = evaluate_tensors(seg, materialize(ds, progress=False), 7)
    assert cms["SegNet"] == plain_seg.cm.tolist()
    _, stretched = E.zero_corruption(frames, [Predictor.load("S", checkpoints["segnet"])])
    assert stretched["S"] != cms["SegNet"]  # the canvas changed what the network saw
