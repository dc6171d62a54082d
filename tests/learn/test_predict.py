"""Prediction from a dataset sample, a taxel frame or an image: class and probability,
segmentation, per-taxel labels (checked against a slow reference of the back-projection rule and
the dataset's own labels) and per-part summaries, the figures, `handskin predict` end to end and
its hand-off to `handskin view`, input errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import typer
from PIL import Image
from typer.testing import CliRunner

from learn.cli import register
from learn.infer.predict import (
    Prediction,
    Predictor,
    attach_taxels,
    load_map,
    load_predictor,
    predict_frame,
    predict_image,
    predict_sample,
    read_frame,
    read_sample,
    save_figures,
)
from sim.cli.view import load_predicted
from tactile.dataset import DatasetWriter, open_dataset
from tactile.errors import DataError
from tactile.images.labels import N_CLASSES, backproject, part_summary
from tactile.images.tactile_map import TactileMap


@pytest.fixture(scope="module")
def predictors(checkpoints):
    torch.set_num_threads(1)
    return load_predictor(checkpoints["handsnet"]), load_predictor(checkpoints["segnet"])


def test_predict_frame_parts_match_part_summary(predictors, tiny_dataset, tmp_path):
    clf, seg = predictors
    tmap, layout, to_pa = load_map(tiny_dataset)
    raw = open_dataset(tiny_dataset).raw[0]  # a hand
    np.savetxt(tmp_path / "frame.csv", raw[None], delimiter=",", fmt="%d")
    p = to_pa(read_frame(tmp_path / "frame.csv", layout))
    pred = predict_frame(p, tmap, clf, seg)
    assert pred.class_name in ("non_hand", "hand") and 0.5 <= pred.probability <= 1.0
    assert pred.segmentation.shape == tmap.shape and pred.taxel_labels.shape == (tmap.n_taxels,)
    assert np.array_equal(pred.taxel_labels, backproject(tmap, pred.segmentation))
    assert pred.parts == part_summary(pred.taxel_labels, p)
    assert (pred.segmentation[tmap.image(p) == 0] == 0).all()
    fig, bars = save_figures(pred, tmp_path / "pred.png")
    assert bars.name == "pred_parts.png"
    assert_picture(fig, (90 * (1.0 + 13 / 4 * tmap.shape[0] / tmap.shape[1]), 90 * 13 / 2))
    assert_picture(bars, (90 * 3.6, 90 * 10))


class Stripes(torch.nn.Module):
    """A fake segmenter: class 1 + (column // 8) % 6 everywhere (one-hot logits)."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        cols = torch.arange(x.shape[-1]) // 8 % 6 + 1
        cls = cols.expand(x.shape[0], *x.shape[-2:])
        return torch.nn.functional.one_hot(cls, 7).movedim(-1, 1).float()


def test_parts_with_a_known_segmenter(tiny_dataset):
    tmap, _, to_pa = load_map(tiny_dataset)
    p = to_pa(open_dataset(tiny_dataset).raw[1])
    seg = Predictor(Stripes(), "segment", (32, 48), ())
    pred = predict_frame(p, tmap, None, seg)
    assert pred.parts == part_summary(backproject(tmap, pred.segmentation), p)
    assert sum(s.n_taxels for s in pred.parts.values()) >= (p > 0).sum() // 2
    assert len({s.n_taxels for s in pred.parts.values()}) > 1
    middle = float(np.median(p[p > 0]))
    above = predict_frame(p, tmap, None, seg, threshold_pa=middle)
    assert above.parts == part_summary(pred.taxel_labels, p, threshold=middle) != pred.parts
    assert np.array_equal(above.taxel_labels, pred.taxel_labels)  # labels do not depend on it


def test_predict_image_and_layout_map(predictors, tiny_dataset, tmp_path):
    clf, _ = predictors
    pred = predict_image(open_dataset(tiny_dataset).image[30], clf)
    assert pred.segmentation is None and pred.class_name in ("non_hand", "hand")
    layout = open_dataset(tiny_dataset).layout
    layout.save(tmp_path / "layout.npz")
    tmap, _, to_pa = load_map(tmp_path / "layout.npz")
    assert tmap.n_taxels == layout.n_taxels and np.array_equal(to_pa(np.ones(3)), np.ones(3))
    with pytest.raises(DataError, match="classifier, a segmenter"):
        predict_image(np.zeros((5, 5), np.uint8))


def test_read_frame_errors(tiny_dataset, tmp_path):
    layout = open_dataset(tiny_dataset).layout
    np.save(tmp_path / "short.npy", np.ones(5))
    with pytest.raises(DataError, match="5 values"):
        read_frame(tmp_path / "short.npy", layout)
    with pytest.raises(DataError, match="no frame file"):
        read_frame(tmp_path / "missing.csv", layout)


def assert_picture(path, size_px) -> None:
    """A PNG of (height, width) ``size_px`` (±1 px) whose pixels vary."""
    rgb = np.asarray(Image.open(path).convert("RGB"))
    assert abs(rgb.shape[0] - size_px[0]) <= 1 and abs(rgb.shape[1] - size_px[1]) <= 1
    assert rgb.std() > 10 and np.mean(np.any(rgb != rgb[0, 0], axis=-1)) > 0.05


def slow_backproject(tmap: TactileMap, seg: np.ndarray, radius_mm: float) -> np.ndarray:
    """The documented rule, taxel by taxel: the most frequent class 1..6 among the pixels whose
    centre lies within ``radius_mm`` of one of the taxel's map vertices; ties to the smaller id;
    0 when there is none."""
    centres = tmap.pixel_centers().reshape(-1, 2)
    flat = seg.reshape(-1)
    out = np.zeros(tmap.n_taxels, np.uint8)
    for t in range(tmap.n_taxels):
        near = np.zeros(len(flat), bool)
        for uv in tmap.vertex_uv_mm[tmap.vertex_taxel == t]:
            near |= np.hypot(*(centres - uv).T) <= radius_mm
        counts = np.bincount(flat[near], minlength=N_CLASSES)[1:]
        out[t] = counts.argmax() + 1 if counts.any() else 0
    return out


def test_ground_truth_segmentation_backprojects_to_the_dataset_labels(tiny_dataset):
    ds = open_dataset(tiny_dataset)
    hands = np.flatnonzero(ds.is_hand[:])[:3]
    for i in hands:
        sample = read_sample(tiny_dataset, int(i))
        pred = attach_taxels(
            Prediction(sample.image, segmentation=sample.true_segmentation),
            sample.tmap,
            sample.pressure,
        )
        reference = slow_backproject(sample.tmap, sample.true_segmentation, 2 * sample.tmap.step_mm)
        assert np.array_equal(pred.taxel_labels, reference)
        active = sample.pressure > 0
        assert np.array_equal(active, sample.true_labels > 0)  # hand samples: pressed = labelled
        assert (pred.taxel_labels[active] > 0).all()  # every pressed taxel lies under the image
        # the label image gives a pixel the part with the largest pressure there; the tiny set
        # presses every taxel of a sample equally hard, so where two parts' dilated fields meet
        # the lower id takes the pixel (ties go to the smaller id, the palm counting as a
        # neighbour of every finger). A misread taxel is therefore read as the palm or the
        # finger before its own, and lies within reach of a pressed taxel of that part: the
        # dilation radius plus the back-projection radius, plus a pixel's diagonal.
        agree = pred.taxel_labels[active] == sample.true_labels[active]
        assert agree.mean() >= 0.9  # only taxels at a border between parts
        read, true = pred.taxel_labels[active][~agree], sample.true_labels[active][~agree]
        assert ((read == 6) | ((read == true - 1) & (true < 6))).all()
        step = sample.tmap.step_mm
        reach = (4 + 2) * step + np.sqrt(2) * step
        centre = np.array(
            [
                sample.tmap.vertex_uv_mm[sample.tmap.vertex_taxel == t].mean(axis=0)
                for t in range(sample.tmap.n_taxels)
            ]
        )
        pressed = np.flatnonzero(active)
        for t, part in zip(pressed[~agree], read, strict=True):
            others = pressed[sample.true_labels[pressed] == part]
            assert np.hypot(*(centre[others] - centre[t]).T).min() <= reach


def test_read_sample_errors(tiny_dataset, tmp_path):
    with pytest.raises(DataError, match="out of range"):
        read_sample(tiny_dataset, 48)
    with pytest.raises(DataError, match="no dataset"):
        read_sample(tmp_path, 0)


def test_predict_command_end_to_end_and_view_hand_off(checkpoints, tiny_dataset, tmp_path):
    app = typer.Typer()
    register(app)
    png, labels = tmp_path / "fig" / "pred.png", tmp_path / "pred33.npy"
    args = [
        "predict",
        str(tiny_dataset),
        "--sample",
        "3",
        "--classifier",
        str(checkpoints["handsnet"]),
        "--segmenter",
        str(checkpoints["segnet"]),
        "--png",
        str(png),
        "--out",
        str(labels),
    ]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 0, res.output
    sample = read_sample(tiny_dataset, 3)
    expected = predict_sample(sample, None, load_predictor(checkpoints["segnet"]))
    saved = np.load(labels)
    assert saved.dtype == np.uint8 and np.array_equal(saved, expected.taxel_labels)
    assert np.array_equal(saved, backproject(sample.tmap, expected.segmentation))
    assert sample.threshold_pa == 0.0  # the tiny dataset records no active threshold
    for name, s in part_summary(saved, sample.pressure).items():
        assert f"{name:7s} {s.n_taxels:5d} taxels" in res.output
    tmap = sample.tmap
    assert_picture(png, (90 * (1.0 + 13 / 4 * tmap.shape[0] / tmap.shape[1]), 90 * 13))
    assert_picture(png.with_name("pred_parts.png"), (90 * 3.6, 90 * 10))
    red = np.all(np.asarray(Image.open(png).convert("RGB")) == (255, 0, 0), axis=-1)
    wrong = (expected.segmentation != sample.true_segmentation).any()
    assert red.any() == wrong
    taxels, pixels = load_predicted(labels, tmap, tmap.n_taxels)  # what handskin view reads
    assert np.array_equal(taxels, saved) and pixels is None


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["{data}", "--segmenter", "{seg}"], "--sample N goes with a dataset folder"),
        (["{data}", "--sample", "99", "--segmenter", "{seg}"], "--sample 99 is out of range"),
        (["{png}", "--sample", "0", "--segmenter", "{seg}"], "--sample N goes with a dataset"),
        (["{png}", "--segmenter", "{seg}", "--out", "{out}/l.npy"], "--out writes per-taxel"),
        (
            ["{data}", "--sample", "0", "--classifier", "{seg}", "--out", "{out}/l.npy"],
            "it needs --segmenter",
        ),
        (["{data}", "--sample", "0", "--segmenter", "{out}/none.pt"], "no checkpoint"),
        (["{frame}", "--segmenter", "{seg}"], "--map goes with a taxel frame"),
        (["{out}/none.csv", "--segmenter", "{seg}"], "no dataset folder or file"),
        (["{seg}", "--segmenter", "{seg}"], "or a frame (.csv, .npy)"),
        (["{data}", "--sample", "0"], "give --classifier, --segmenter or both"),
        (["{data}", "--sample", "0", "--segmenter", "{seg}", "--int8"], "give --classifier"),
    ],
)
def test_predict_command_errors_before_work(checkpoints, tiny_dataset, tmp_path, args, message):
    app = typer.Typer()
    register(app)
    png, frame = tmp_path / "image.png", tmp_path / "frame.csv"
    png.write_bytes(b"")
    frame.write_text("0, 1, 2\n")
    fill = {"data": tiny_dataset, "seg": checkpoints["segnet"], "out": tmp_path / "out"}
    fill |= {"png": png, "frame": frame}
    res = CliRunner().invoke(app, ["predict", *[a.format(**fill) for a in args]])
    assert res.exit_code == 2 and message in res.output, res.output
    assert not (tmp_path / "out").exists()


def test_classifier_only_figure(predictors, tiny_dataset, tmp_path):
    clf, _ = predictors
    pred = predict_sample(read_sample(tiny_dataset, 30), clf)
    assert pred.taxel_labels is None and pred.true_segmentation is not None
    (fig,) = save_figures(pred, tmp_path / "c.png")
    h, w = pred.image.shape
    assert_picture(fig, (90 * (1.0 + 13 / 4 * h / w), 90 * 13 / 4))


def test_parts_count_taxels_above_the_datasets_active_threshold(tiny_dataset, tmp_path):
    """A synthetic dataset records its active-taxel threshold (config ``episode.active_pa``);
    the per-part summary of a dataset sample counts only the taxels above it."""
    src = open_dataset(tiny_dataset)
    fields = (
        "raw",
        "pressure_pa",
        "image",
        "taxel_label",
        "label_image",
        "is_hand",
        "subject_id",
        "instance_id",
    )
    samples = [{f: src[f][i] for f in fields} for i in (0, 30)]
    pressure = src.pressure_from_raw(samples[0]["raw"])
    threshold = float(np.median(pressure[pressure > 0]))
    gain = {"skin_counts_per_pa": src.attrs["skin_counts_per_pa"]}
    writer = DatasetWriter(
        tmp_path / "ds",
        config={"episode": {"active_pa": threshold}},
        part="sector",
        generator_version="t",
        seed=0,
        tmap=src.map,
        layout=src.layout,
        attrs=gain,
    )
    writer.write_chunk(0, samples)
    writer.merge()
    sample = read_sample(tmp_path / "ds", 0)
    assert sample.threshold_pa == threshold and np.array_equal(sample.pressure, pressure)
    pred = predict_sample(sample, None, Predictor(Stripes(), "segment", (32, 48), ()))
    assert pred.parts == part_summary(pred.taxel_labels, pressure, threshold=threshold)
    assert pred.parts != part_summary(pred.taxel_labels, pressure)
