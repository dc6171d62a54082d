"""Prediction from a taxel frame or an image: class and probability, segmentation, per-taxel
labels and per-part summaries consistent with tactile.labels, the picture, input errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from learn.predict import (
    Predictor,
    load_map,
    load_predictor,
    predict_frame,
    predict_image,
    read_frame,
    save_picture,
)
from tactile.dataset import open_dataset
from tactile.errors import DataError
from tactile.labels import backproject, part_summary


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
    assert save_picture(pred, tmp_path / "pred.png").stat().st_size > 1000


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
