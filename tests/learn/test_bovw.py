"""Bag of visual words: descriptors' layout, blank-image fallback, and a tiny problem it solves."""

from __future__ import annotations

import numpy as np
import pytest
from skimage.draw import disk, line_aa

from learn.bovw import BagOfVisualWords, dense_descriptors, image_descriptors, word_histogram
from learn.config import BovwConfig
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
