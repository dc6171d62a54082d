"""Input canvas (`ModelConfig.canvas_mm`): every tactile image centred on a canvas of fixed
millimetres before the resize, so a print covers the same input pixels on any part's map.
Checked against hand-made padding and crops (numpy), a closed-form print size, and the
round trip of `handskin predict`'s segmentation back onto the map."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from learn.config import ModelConfig, run_from_dict
from learn.data.dataset import TorchTactileDataset
from learn.data.load import open_split
from learn.infer.ensemble import load_members
from learn.infer.predict import Predictor, predict_image, segment
from learn.inputs import net_input, net_labels
from tactile.config import to_dict
from tactile.errors import ConfigError
from tactile.images.resize import canvas_px, fit_canvas, resize_grey, resize_labels

from .conftest import SIZE


def slow_fit(img: np.ndarray, canvas: tuple[int, int]) -> np.ndarray:
    """Reference: pixel by pixel, the margin split as floor(|difference| / 2) before the image
    (padding) or cut from its start (cropping)."""
    out = np.zeros(canvas, img.dtype)
    (h, w), (ch, cw) = img.shape, canvas
    dr = (ch - h) // 2 if ch >= h else -((h - ch) // 2)
    dc = (cw - w) // 2 if cw >= w else -((w - cw) // 2)
    for i in range(h):
        for j in range(w):
            if 0 <= i + dr < ch and 0 <= j + dc < cw:
                out[i + dr, j + dc] = img[i, j]
    return out


@pytest.mark.parametrize("canvas", [(9, 12), (10, 13), (4, 5), (3, 14), (6, 8)])
def test_fit_canvas_matches_a_pixel_loop(canvas):
    rng = np.random.default_rng(1)
    img = rng.integers(1, 255, (6, 8)).astype(np.uint8)
    np.testing.assert_array_equal(fit_canvas(img, canvas), slow_fit(img, canvas))
    batch = rng.random((3, 6, 8)).astype(np.float32)
    got = fit_canvas(batch, canvas)
    assert got.dtype == np.float32 and got.shape == (3, *canvas)
    for b in range(3):
        np.testing.assert_array_equal(got[b], slow_fit(batch[b], canvas))
    if canvas[0] >= 6 and canvas[1] >= 8:  # padding only: the way back is the same function
        np.testing.assert_array_equal(fit_canvas(fit_canvas(img, canvas), img.shape), img)


def test_canvas_px_rounds_and_refuses_a_bad_step():
    assert canvas_px((229.0, 383.0), 1.0) == (229, 383)
    assert canvas_px((229.0, 383.0), 2.0) == (114, 192)  # 114.5 rounds to even, 191.5 too
    assert canvas_px((0.2, 3.0), 1.0) == (1, 3)
    with pytest.raises(ConfigError, match="grid step must be > 0 mm"):
        canvas_px((10.0, 10.0), 0.0)


def square_print(map_shape: tuple[int, int], side: int = 20) -> np.ndarray:
    """(H, W) uint8 image: a side × side px square pressed at the map's centre (level 255)."""
    img = np.zeros(map_shape, np.uint8)
    r, c = (map_shape[0] - side) // 2, (map_shape[1] - side) // 2
    img[r : r + side, c : c + side] = 255
    return img


def test_a_print_covers_the_same_input_pixels_on_a_smaller_map():
    """A 20 × 20 mm square on a 100 × 160 mm map and on a 50 × 80 mm one, both at 1 mm per px,
    into a 20 × 32 px input. Stretched, the smaller map doubles the print (4 × 4 -> 8 × 8 input
    pixels); on a 100 × 160 mm canvas both cover 4 × 4 = 16 (20 mm × 0.2 px/mm)."""
    big, small = square_print((100, 160)), square_print((50, 80))
    size, canvas = (20, 32), (100, 160)
    count = [int((net_input(m, size, "segment") > 0).sum()) for m in (big, small)]
    assert count == [16, 64]
    on_canvas = [net_input(m, size, "segment", canvas) for m in (big, small)]
    assert [int((x > 0).sum()) for x in on_canvas] == [16, 16]
    np.testing.assert_array_equal(on_canvas[0], on_canvas[1])


def test_dataset_inputs_and_labels_on_a_canvas_match_hand_made_padding(tiny_dataset):
    """`TorchTactileDataset` with ``canvas_mm`` against np.pad / slicing of the stored images
    (the tiny map is 1 mm per px), for classification and segmentation; segmentation inputs stay
    on their labels' support."""
    canvas = (40, 130)  # shorter than the tiny map (crop rows), wider (pad columns)
    ds = TorchTactileDataset(tiny_dataset, "train", "segment", SIZE, flips=False, canvas_mm=canvas)
    clf = TorchTactileDataset(
        tiny_dataset, "train", "classify", SIZE, flips=False, canvas_mm=canvas
    )
    assert ds.reader.map.step_mm == 1.0
    for k in range(3):
        i = int(ds.indices[k])
        image, labels = ds.reader.image[i], ds.reader.label_image[i]
        h, w = image.shape
        assert h > canvas[0] and w < canvas[1]
        top, left = (h - canvas[0]) // 2, (canvas[1] - w) // 2
        rows = slice(top, top + canvas[0])
        widths = ((0, 0), (left, canvas[1] - w - left))
        ref_img = np.pad(image[rows], widths)
        ref_lbl = np.pad(labels[rows], widths)
        x, y = ds[k]
        np.testing.assert_array_equal(x[0].numpy(), resize_grey(ref_img, SIZE, keep_support=True))
        np.testing.assert_array_equal(y.numpy(), resize_labels(ref_lbl, SIZE))
        assert np.array_equal(x[0].numpy() > 0, y.numpy() > 0)
        j = list(clf.indices).index(i)
        np.testing.assert_array_equal(clf[j][0][0].numpy(), resize_grey(ref_img, SIZE))
    np.testing.assert_array_equal(net_labels(ref_lbl, SIZE), resize_labels(ref_lbl, SIZE))


class PressedIsPalm(nn.Module):
    """Segmenter: palm (6) where the input is pressed, background elsewhere."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = torch.zeros(len(x), 7, *x.shape[-2:])
        out[:, 6] = (x[:, 0] > 0).float()
        out[:, 0] = 0.5
        return out


@pytest.mark.parametrize("canvas_mm", [(60.0, 200.0), (120.0, 120.0)])
def test_predicted_segmentation_lands_back_on_the_print(canvas_mm):
    """The segmenter's labels go back through the canvas onto the map grid: a print off-centre
    on a 50 × 150 mm map at 2 mm per px is labelled palm on most of its pixels (all but a row or
    column lost to the input's coarser grid). Put back
    without undoing the canvas, the labels would miss it."""
    img = np.zeros((25, 75), np.uint8)
    img[4:12, 50:66] = 200  # 16 × 32 mm, off-centre
    seg = Predictor(PressedIsPalm(), "segment", (30, 60), (), canvas_mm)
    labels = segment(img, seg, step_mm=2.0)
    pressed = img > 0
    assert (labels[pressed] == 6).mean() > 0.8 and (labels[~pressed] == 0).all()
    wrong = Predictor(PressedIsPalm(), "segment", (30, 60), ())  # no canvas: stretched
    lost = resize_labels(seg.logits(img, 2.0).argmax(0).numpy(), img.shape)
    assert (lost[pressed] == 6).mean() < 0.5  # the stretched read of the canvas labels misses
    assert (segment(img, wrong)[pressed] == 6).all()  # a stretched model is unchanged
    assert np.array_equal(predict_image(img, None, seg, 2.0).segmentation, labels)


def test_canvas_config_round_trip_and_errors(tiny_dataset, tmp_path, checkpoints):
    model = ModelConfig("segnet", 7, width=0.125, input_size=SIZE, canvas_mm=(229, 383))
    run = run_from_dict({"model": to_dict(model)})
    assert run.model.canvas_mm == (229.0, 383.0)
    assert run_from_dict({}).model.canvas_mm is None  # older checkpoints: stretched
    with pytest.raises(ConfigError, match=r"canvas_mm = \(0.0, 3.0\).*\[229, 383\]"):
        run_from_dict({"model": {"canvas_mm": [0, 3]}})
    (tmp_path / "hand").mkdir()
    with pytest.raises(ConfigError, match=r"image folder.*no known size in mm.*Fix"):
        open_split(tmp_path, "test", "classify", SIZE, None, 0, canvas_mm=(50.0, 80.0))
    ckpt = torch.load(checkpoints["segnet"], weights_only=True)
    ckpt["config"]["model"]["canvas_mm"] = [50.0, 80.0]
    torch.save(ckpt, tmp_path / "canvas.pt")
    with pytest.raises(ConfigError, match=r"input canvas .* Fix"):
        load_members([checkpoints["segnet"], tmp_path / "canvas.pt"])


def test_evaluate_scores_a_canvas_model_on_its_canvas(tiny_dataset, tmp_path, checkpoints):
    """`handskin evaluate` on a segmenter with a canvas: its scores are those of the network on
    `TorchTactileDataset` inputs made on that canvas (not the stretched ones), the report says
    which canvas, and the error sheet is drawn."""
    import json

    import typer
    from typer.testing import CliRunner

    from learn.cli import register
    from learn.data.load import materialize
    from learn.train.checkpoint import load_checkpoint, model_from_checkpoint
    from learn.train.validation import evaluate_tensors

    ckpt = torch.load(checkpoints["segnet"], weights_only=True)
    ckpt["config"]["model"]["canvas_mm"] = [50.0, 120.0]
    torch.save(ckpt, tmp_path / "canvas.pt")
    app = typer.Typer()
    register(app)
    md = tmp_path / "r.md"
    res = CliRunner().invoke(
        app,
        ["evaluate", str(tiny_dataset), str(tmp_path / "canvas.pt"), "--out", str(md)],
    )
    assert res.exit_code == 0, res.output
    row = json.loads(md.with_suffix(".json").read_text())[0]
    model, _ = model_from_checkpoint(load_checkpoint(tmp_path / "canvas.pt"))
    ds = TorchTactileDataset(
        tiny_dataset, "test", "segment", SIZE, flips=False, canvas_mm=(50.0, 120.0)
    )
    ref = evaluate_tensors(model, materialize(ds, progress=False), 7)
    assert row["cm"] == ref.cm.tolist() and row["canvas_mm"] == [50.0, 120.0]
    plain = TorchTactileDataset(tiny_dataset, "test", "segment", SIZE, flips=False)
    assert evaluate_tensors(model, materialize(plain, progress=False), 7).cm.tolist() != row["cm"]
    assert "of a 50 × 120 mm canvas" in md.read_text()


def test_vgg_svm_refuses_a_canvas_checkpoint(tmp_path):
    """VGG16 + SVM extracts features from stretched images, so a VGG16 trained on a canvas is
    refused with the fix instead of being fed inputs it never saw."""
    from learn.classical.vgg_svm import VggSvmClassifier
    from learn.config import RunConfig
    from learn.models import create_model
    from learn.train.checkpoint import make_checkpoint, save_checkpoint

    model = ModelConfig("vgg16", 2, width=0.0625, input_size=SIZE, canvas_mm=(50.0, 80.0))
    run = RunConfig(model=model)
    net = create_model("vgg16", **model.kwargs())
    path = save_checkpoint(
        make_checkpoint(net, to_dict(run), epoch=1, best_metric=0.5), tmp_path / "vgg.pt"
    )
    with pytest.raises(ConfigError, match=r"canvas; VGG16 \+ SVM reads images stretched.*Fix"):
        VggSvmClassifier.from_checkpoint(path)
