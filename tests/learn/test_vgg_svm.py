"""VGG16 + SVM trained from a vgg16 checkpoint, saved, loaded, evaluated and reported in Table 3's
row; its errors ranked by the SVM's own margin."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from learn.classical.run import (
    confusion,
    evaluate_classical,
    load_classical,
    split_images,
    train_classical,
)
from learn.classical.svm import MODEL_FILE
from learn.classical.vgg_svm import VggSvmClassifier
from learn.config import VggSvmConfig
from learn.data.load import load_data
from learn.evaluate.report import write_report
from learn.evaluate.scoring import evaluate_checkpoint
from learn.train.loop import fit
from tactile.errors import ConfigError


@pytest.fixture(scope="module")
def vgg16_checkpoint(tiny_dataset, tiny_run, tmp_path_factory):
    """A width-0.125 vgg16 trained one epoch on the tiny dataset."""
    torch.set_num_threads(1)
    run = tiny_run("vgg16", epochs=1)
    folder = tmp_path_factory.mktemp("vgg16")
    fit(run, load_data(tiny_dataset, run), folder, progress=False)
    return folder / "best.pt"


def test_vgg_svm_train_save_load_evaluate(vgg16_checkpoint, checkpoints, tiny_dataset, tmp_path):
    out = tmp_path / "vgg_svm"
    report = train_classical(
        "vgg_svm", tiny_dataset, out, seed=1, init=vgg16_checkpoint, progress=False
    )
    loaded = load_classical(out / MODEL_FILE)
    assert loaded.input_size == (32, 48) and loaded.seed == 1
    fresh = VggSvmClassifier.from_checkpoint(vgg16_checkpoint, VggSvmConfig(), seed=1)
    fresh.fit(*split_images(tiny_dataset, "train", (32, 48))[:2])
    x, y, _ = split_images(tiny_dataset, "test", (32, 48))
    np.testing.assert_array_equal(loaded.predict(x), fresh.predict(x))
    np.testing.assert_allclose(
        loaded.decision_function(x), fresh.decision_function(x), rtol=1e-6, atol=1e-6
    )
    np.testing.assert_allclose(loaded.features(x), fresh.features(x))  # the weights came back
    row = evaluate_classical(out / MODEL_FILE, tiny_dataset, time_runs=3)
    assert row["test_data"] == str(tiny_dataset)
    assert row["cm"] == report["test_confusion"] == confusion(y, fresh.predict(x), 2).tolist()
    rows = [row, evaluate_checkpoint(checkpoints["handsnet"], tiny_dataset, time_runs=3)]
    text = write_report(rows, tmp_path / "r.md").read_text()
    acc = 100 * float((fresh.predict(x) == y).mean())
    assert f"| VGG16 + SVM | {acc:.2f} | {row['ms_per_image']['fast']:.2f} | unknown |" in text
    assert "| HandsNet | " in text and "| BoVW | not run |" in text
    assert row["time_rounds"] == 3
    assert json.loads((out / "test_metrics.json").read_text())["seed"] == 1


def test_vgg_svm_needs_a_vgg16_checkpoint(checkpoints, tiny_dataset, tmp_path):
    with pytest.raises(ConfigError, match="needs a vgg16 one"):
        train_classical("vgg_svm", tiny_dataset, tmp_path, init=checkpoints["handsnet"])
    assert not (tmp_path / MODEL_FILE).exists()
