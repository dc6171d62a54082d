"""Bag of visual words: descriptors' layout, blank-image fallback, a tiny problem it solves;
the arrays that replace sklearn's objects against sklearn / a distance table; `handskin train
--arch bovw` → model.npz → load → `handskin evaluate` (Table 3's BoVW row) on the tiny dataset."""

from __future__ import annotations

import json

import numpy as np
import pytest
import typer
from PIL import Image
from scipy.spatial.distance import cdist
from skimage.draw import disk, line_aa
from sklearn.svm import LinearSVC
from typer.testing import CliRunner

from learn.classical.bovw import (
    BagOfVisualWords,
    dense_descriptors,
    image_descriptors,
    nearest_words,
    word_histogram,
)
from learn.classical.run import confusion, load_classical, real_hand_scores, split_images
from learn.classical.svm import MODEL_FILE, LinearSvm
from learn.cli import register
from learn.config import BovwConfig
from tactile.dataset import open_dataset
from tactile.errors import ConfigError, DataError


def blobs(rng: np.random.Generator, shape=(40, 60)) -> np.ndarray:
    """Class 0: a few round contacts (fingertip-like)."""
    img = np.zeros(shape)
    for _ in range(rng.integers(2, 5)):
        center = (rng.integers(5, shape[0] - 5), rng.integers(5, shape[1] - 5))
        rr, cc = disk(center, 4, shape=shape)
        img[rr, cc] = rng.uniform(0.5, 1.0)
    return img


def bars(rng: np.random.Generator, shape=(40, 60)) -> np.ndarray:
    """Class 1: a few thin straight edges (object-like)."""
    img = np.zeros(shape)
    for _ in range(rng.integers(2, 4)):
        r0, r1 = rng.integers(0, shape[0], 2)
        c0, c1 = rng.integers(0, shape[1], 2)
        rr, cc, val = line_aa(r0, c0, r1, c1)
        img[rr, cc] = np.maximum(img[rr, cc], val)
    return img


def dataset(seed: int, n_per_class: int) -> tuple[list[np.ndarray], np.ndarray]:
    rng = np.random.default_rng(seed)
    images = [blobs(rng) for _ in range(n_per_class)] + [bars(rng) for _ in range(n_per_class)]
    return images, np.repeat([0, 1], n_per_class)


def test_dense_descriptors_have_sift_layout():
    desc = dense_descriptors(np.random.default_rng(0).random((28, 50)), step_px=4, patch_px=16)
    assert desc.shape == (4 * 9, 128)
    np.testing.assert_allclose(np.linalg.norm(desc, axis=1), 1.0)
    assert dense_descriptors(np.zeros((5, 7))).shape == (1, 128)  # padded up to one patch


def test_vertical_edge_votes_for_one_orientation():
    img = np.zeros((16, 16))
    img[:, 8:] = 1.0  # gradient along +x only: orientation bin 0
    desc = dense_descriptors(img).reshape(4, 4, 8)
    assert desc[..., 0].sum() > 0 and desc[..., 1:].sum() == 0


def test_blank_and_tiny_images_fall_back_to_dense():
    for image in (np.zeros((68, 100)), np.zeros((3, 3), np.uint8)):
        desc = image_descriptors(image, BovwConfig())
        assert desc.ndim == 2 and desc.shape[1] == 128


def test_word_histogram():
    expected = np.array([2, 0, 1, 0]) / np.sqrt(5)
    np.testing.assert_allclose(word_histogram(np.array([0, 0, 2]), 4), expected)
    assert word_histogram(np.array([], int), 3).tolist() == [0, 0, 0]


@pytest.mark.parametrize("detector", ["sift", "dense"])
def test_solves_tiny_synthetic_problem(detector):
    cfg = BovwConfig(vocabulary_size=30, detector=detector)
    train, y_train = dataset(0, 40)
    test, y_test = dataset(1, 30)
    model = BagOfVisualWords(cfg).fit(train, y_train)
    assert model.transform(test[:2]).shape == (2, 30)
    assert (model.predict(test) == y_test).mean() >= 0.9


def test_errors():
    with pytest.raises(ConfigError, match="detector"):
        BovwConfig(detector="orb")
    with pytest.raises(DataError, match="vocabulary_size"):
        BagOfVisualWords(BovwConfig(vocabulary_size=500)).fit([np.zeros((16, 16))] * 2, [0, 1])
    with pytest.raises(DataError, match="fit"):
        BagOfVisualWords().predict([np.zeros((16, 16))])


def test_nearest_words_match_a_distance_table():
    rng = np.random.default_rng(3)
    desc, vocabulary = rng.random((200, 128)), rng.random((17, 128))
    expected = cdist(desc, vocabulary).argmin(axis=1)
    assert np.array_equal(nearest_words(desc, vocabulary), expected)


@pytest.mark.parametrize("n_classes", [2, 3])
def test_linear_svm_arrays_match_sklearn(n_classes):
    rng = np.random.default_rng(n_classes)
    x, y = rng.normal(size=(90, 5)), np.arange(90) % n_classes + 4  # ids need not start at 0
    x[:, 0] += 2.0 * y
    svc = LinearSVC(random_state=0).fit(x, y)
    svm = LinearSvm.from_sklearn(svc)
    np.testing.assert_allclose(svm.decision_function(x), svc.decision_function(x), atol=1e-10)
    assert np.array_equal(svm.predict(x), svc.predict(x))


TINY_BOVW = "input_size = [32, 48]\nvocabulary_size = 20\n"  # small images, few words: fast


@pytest.fixture(scope="module")
def bovw_run(tiny_dataset, tmp_path_factory):
    """`handskin train --arch bovw` on the tiny dataset: the run folder."""
    folder = tmp_path_factory.mktemp("bovw")
    (folder / "bovw.toml").write_text(TINY_BOVW)
    app = typer.Typer()
    register(app)
    res = CliRunner().invoke(
        app,
        [
            "train",
            str(tiny_dataset),
            "--out",
            str(folder / "run"),
            "--arch",
            "bovw",
            "--config",
            str(folder / "bovw.toml"),
            "--seed",
            "2",
            "--no-progress",
        ],
    )
    assert res.exit_code == 0, res.output
    return folder / "run"


def test_bovw_train_save_load_gives_the_fitted_model(bovw_run, tiny_dataset):
    loaded = load_classical(bovw_run / MODEL_FILE)
    assert loaded.meta["kind"] == "bovw" and loaded.meta["seed"] == 2
    assert loaded.cfg == BovwConfig(vocabulary_size=20, seed=2)
    x, y, _ = split_images(tiny_dataset, "train", (32, 48))
    fresh = BagOfVisualWords(BovwConfig(vocabulary_size=20, seed=2)).fit(x, y)  # same seed
    test_x, test_y, names = split_images(tiny_dataset, "test", (32, 48))
    assert names == ("non_hand", "hand")
    np.testing.assert_array_equal(loaded.predict(test_x), fresh.predict(test_x))
    np.testing.assert_allclose(loaded.decision_function(test_x), fresh.decision_function(test_x))
    report = json.loads((bovw_run / "test_metrics.json").read_text())
    pred = loaded.predict(test_x)
    assert report["test_confusion"] == confusion(test_y, pred, 2).tolist()
    assert report["test_metrics"]["accuracy"] == pytest.approx((pred == test_y).mean())


def test_evaluate_fills_the_bovw_row(bovw_run, tiny_dataset, tmp_path):
    app = typer.Typer()
    register(app)
    md = tmp_path / "report.md"
    res = CliRunner().invoke(
        app,
        ["evaluate", str(tiny_dataset), str(bovw_run / MODEL_FILE), "--out", str(md)],
    )
    assert res.exit_code == 0, res.output
    (row,) = json.loads(md.with_suffix(".json").read_text())
    ds = open_dataset(tiny_dataset)
    is_hand = ds.is_hand[:][ds.splits["test"]]
    assert np.array(row["cm"]).sum(axis=1).tolist() == np.bincount(is_hand, minlength=2).tolist()
    test_x, test_y, _ = split_images(tiny_dataset, "test", (32, 48), seed=2)
    accuracy = (load_classical(bovw_run / MODEL_FILE).predict(test_x) == test_y).mean()
    assert row["metrics"]["accuracy"] == pytest.approx(accuracy) and row["ms_per_image"]["fast"] > 0
    text = md.read_text()
    assert f"| BoVW | {100 * accuracy:.2f} | {row['ms_per_image']['fast']:.2f} |" in text
    assert "| VGG16 + SVM | not run |" in text and "descriptors, visual words, SVM" in text


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--lr", "0.1"], "--lr does not apply to --arch bovw"),
        (["--epochs", "3"], "apply to --arch vgg_svm only"),
        (["--config", "{bad}"], "unknown key 'vocab'"),
    ],
)
def test_bovw_option_errors_before_work(tiny_dataset, tmp_path, extra, message):
    (tmp_path / "bad.toml").write_text("vocab = 3\n")
    app = typer.Typer()
    register(app)
    args = [
        "train",
        str(tiny_dataset),
        "--out",
        str(tmp_path / "out"),
        "--arch",
        "bovw",
        *[a.format(bad=tmp_path / "bad.toml") for a in extra],
    ]
    res = CliRunner().invoke(app, args)
    assert res.exit_code == 2 and message in res.output, res.output
    assert not (tmp_path / "out").exists()


def test_model_file_errors(tmp_path):
    with pytest.raises(DataError, match="no model file"):
        load_classical(tmp_path / "none.npz")
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(DataError, match="not a handskin classical model"):
        load_classical(tmp_path / "other.npz")


def test_bovw_scored_on_real_box_prints_as_on_its_test_split(bovw_run, tiny_dataset, tmp_path):
    """Hand recall on a box folder of the test split's hand prints (one palm box each) and
    specificity on its non-hands, against the model's answers through the training data path."""
    model = load_classical(bovw_run / MODEL_FILE)
    x, y, _ = split_images(tiny_dataset, "test", (32, 48))
    said = model.predict(x)
    (tmp_path / "images").mkdir()
    (tmp_path / "labels").mkdir()
    with open_dataset(tiny_dataset) as ds:
        test = np.sort(np.asarray(ds.splits["test"]))
        hands = test[ds.is_hand[:][test] == 1]
        for i in hands.tolist():
            Image.fromarray(np.asarray(ds.image[i])).save(tmp_path / "images" / f"{i}.png")
            (tmp_path / "labels" / f"{i}.txt").write_text("5 0.5 0.5 1 1\n")
    (tmp_path / "data.yaml").write_text("names: [thumb, index, middle, ring, pinkie, palm]\n")
    row = real_hand_scores(bovw_run / MODEL_FILE, tmp_path, tiny_dataset)
    assert row["task"] == "classify" and row["n_real"] == len(hands) == int((y == 1).sum())
    assert row["hand_recall"] == pytest.approx(np.mean(said[y == 1] == 1))
    assert row["n_non_hand"] == int((y == 0).sum())
    assert row["specificity"] == pytest.approx(np.mean(said[y == 0] == 0))
