"""Image-folder datasets: classes from folders, hand/non-hand mapping, seeded stratified split,
label PNGs (palette or ids), and TaISLab training end to end (skipped without the data)."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from PIL import Image

from learn.config import ModelConfig, RunConfig, TrainConfig
from learn.data.folder import FolderDataset, read_label_png
from learn.data.load import load_data
from learn.train.loop import fit
from learn.train.validation import evaluate_tensors
from tactile.errors import DataError
from tactile.images.labels import PALETTE, colorize


@pytest.fixture
def folder(tmp_path):
    """images/{a,b,c}/k.png (6 each, 10 × 14 px; a bright left half for class a) + labels."""
    rng = np.random.default_rng(0)
    for cls in "abc":
        (tmp_path / "images" / cls).mkdir(parents=True)
        (tmp_path / "labels" / cls).mkdir(parents=True)
        for k in range(6):
            img = rng.integers(0, 50, (10, 14), dtype=np.uint8)
            img[:, :7] += 200 if cls == "a" else 0
            Image.fromarray(img).save(tmp_path / "images" / cls / f"{k}.png")
            lab = np.zeros((10, 14), np.uint8)
            lab[:5] = k % 7
            Image.fromarray(colorize(lab)).save(tmp_path / "labels" / cls / f"{k}.png")
    return tmp_path


def test_classes_flips_and_split(folder):
    ds = FolderDataset(folder, split="train", size=(20, 28))
    test = FolderDataset(folder, split="test", size=(20, 28), flips=False)
    assert ds.class_names == ("a", "b", "c") and len(ds) == 3 * 12 and len(test) == 6
    assert set(ds.indices).isdisjoint(test.indices)
    assert np.bincount(ds.targets[test.indices]).tolist() == [2, 2, 2]  # stratified
    (x0, y0), (x1, _), (x2, _) = ds[0], ds[1], ds[2]
    assert x0.shape == (1, 20, 28) and x0.dtype == torch.float32 and 0 <= x0.min() <= x0.max() <= 1
    assert torch.equal(x1, x0.flip(-1)) and torch.equal(x2, x0.flip(-2))
    assert int(y0) == ds.targets[ds.indices[0]]
    again = FolderDataset(folder, split="test", size=(20, 28), flips=False)
    assert np.array_equal(again.indices, test.indices)  # seeded


def test_hand_classes_and_errors(folder):
    ds = FolderDataset(folder, split=None, hand_classes=("a",), flips=False)
    assert ds.class_names == ("non_hand", "hand") and ds.targets.sum() == 6
    with pytest.raises(DataError, match="hand classes"):
        FolderDataset(folder, hand_classes=("hand",))
    with pytest.raises(DataError, match="no image folder"):
        FolderDataset(folder / "missing")


def test_segmentation_labels(folder, tmp_path):
    ds = FolderDataset(folder, split=None, task="segment", size=(10, 14), flips=False)
    _, y = ds[3]
    assert y.shape == (10, 14) and y.dtype == torch.int64
    assert (y[:5] == 3).all() and (y[5:] == 0).all()
    Image.fromarray(np.full((4, 4), 5, np.uint8)).save(tmp_path / "ids.png")
    assert (read_label_png(tmp_path / "ids.png") == 5).all()
    rgb = np.zeros((4, 4, 3), np.uint8)
    rgb[0, 0] = [1, 2, 3]
    Image.fromarray(rgb).save(tmp_path / "bad.png")
    with pytest.raises(DataError, match="PALETTE"):
        read_label_png(tmp_path / "bad.png")
    assert PALETTE.shape == (7, 3)


def test_taislab_hand_vs_rest(shared_data):
    root = shared_data / "taislab"
    if not (root / "images").is_dir():
        pytest.skip(f"TaISLab images not found at {root / 'images'}")
    torch.set_num_threads(1)
    run = RunConfig(
        model=ModelConfig("handsnet", 2, input_size=(28, 50)),
        train=TrainConfig(epochs=3, batch_size=32),
        flips=False,
        threads=1,
    )
    data = load_data(root, run, hand_classes=("hand", "finger"))
    assert data.class_names == ("non_hand", "hand") and len(data.test.y) == 330
    result = fit(run, data, None, progress=False)
    scores = evaluate_tensors(result.model, data.test, 2).metrics
    assert scores["mean_accuracy"] > 0.8  # balanced chance: 0.5; hands are 9 % of the images


def test_every_folder_its_own_class_keeps_a_validation_split(folder):
    """A folder of more than two classes (TaISLab's 22) is split for validation per image, as
    two classes are: no split is left empty (it was: "a data split is empty")."""
    run = RunConfig(
        model=ModelConfig("handsnet", 3, input_size=(10, 14)),
        train=TrainConfig(epochs=1, batch_size=4),
        flips=False,
        val_fraction=0.3,
    )
    data = load_data(folder, run, progress=False)
    assert data.class_names == ("a", "b", "c")
    assert len(data.val.y) > 0 and len(data.train.y) > len(data.val.y)
    assert len(data.train.y) + len(data.val.y) == 12  # the 12 train images, each used once
