"""Bag of visual words: SIFT descriptors (128) → k-means vocabulary → word histogram → linear SVM.

SIFT comes from ``skimage.feature.SIFT``. It finds no keypoint on blank or nearly flat images
(and few on tiny ones) and then raises; such an image falls back to *dense* descriptors: the
same 4 × 4 cells × 8 orientations gradient histogram (normalised, clipped at 0.2, renormalised)
on a regular grid, without keypoint detection or rotation. Dense grids are also what MATLAB's
``bagOfFeatures`` uses by default, so ``detector="dense"`` is available for every image.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict

import numpy as np
from skimage.feature import SIFT
from skimage.util import img_as_float
from sklearn.cluster import MiniBatchKMeans
from sklearn.svm import LinearSVC

from learn.classical.svm import LinearSvm
from learn.config import BovwConfig
from tactile.config import from_dict
from tactile.errors import DataError

N_BINS = 8  # orientations per cell, as SIFT
N_CELLS = 4  # cells per patch side, as SIFT: 4 × 4 × 8 = 128
Images = Sequence[np.ndarray] | np.ndarray  # (H, W) images, or an (N, H, W) stack


def _normalise(desc: np.ndarray) -> np.ndarray:
    """SIFT's normalisation of ``(N, 128)`` rows: unit L2, clip at 0.2, unit L2 (zeros stay)."""
    desc = desc / np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-12)
    desc = np.minimum(desc, 0.2)
    return desc / np.maximum(np.linalg.norm(desc, axis=1, keepdims=True), 1e-12)


def _cell_histograms(image: np.ndarray, cell_px: int) -> np.ndarray:
    """``(8, H − c + 1, W − c + 1)``: magnitude-weighted orientation histogram of each c × c box."""
    gy, gx = np.gradient(image)
    magnitude = np.hypot(gx, gy)
    bins = (np.arctan2(gy, gx) % (2 * np.pi) / (2 * np.pi) * N_BINS).astype(int) % N_BINS
    votes = np.zeros((N_BINS, *image.shape))
    np.put_along_axis(votes, bins[None], magnitude[None], axis=0)
    integral = np.pad(votes.cumsum(1).cumsum(2), ((0, 0), (1, 0), (1, 0)))
    c = cell_px
    return integral[:, c:, c:] - integral[:, :-c, c:] - integral[:, c:, :-c] + integral[:, :-c, :-c]


def dense_descriptors(image: np.ndarray, step_px: int = 4, patch_px: int = 16) -> np.ndarray:
    """SIFT-layout descriptors ``(N, 128)`` float on a grid of ``patch_px`` patches.

    image : ``(H, W)`` grey, any dtype (converted to float in [0, 1]); zero-padded at the
    bottom/right up to one patch. Patches start every ``step_px`` pixels.
    """
    img = img_as_float(np.asarray(image))
    img = np.pad(img, [(0, max(0, patch_px - s)) for s in img.shape])
    cell = patch_px // N_CELLS
    boxes = _cell_histograms(img, cell)
    r0 = np.arange(0, img.shape[0] - patch_px + 1, step_px)
    c0 = np.arange(0, img.shape[1] - patch_px + 1, step_px)
    offsets = cell * np.arange(N_CELLS)
    rows = (r0[:, None] + offsets)[:, None, :, None]  # (R, 1, 4, 1)
    cols = (c0[:, None] + offsets)[None, :, None, :]  # (1, C, 1, 4)
    desc = boxes[:, rows, cols]  # (8, R, C, 4, 4)
    desc = desc.transpose(1, 2, 3, 4, 0).reshape(-1, N_CELLS * N_CELLS * N_BINS)
    return _normalise(desc)


def image_descriptors(image: np.ndarray, cfg: BovwConfig | None = None) -> np.ndarray:
    """``(N, 128)`` float descriptors of one ``(H, W)`` image (SIFT, dense fallback)."""
    cfg = cfg or BovwConfig()
    img = img_as_float(np.asarray(image))
    if cfg.detector == "sift":
        sift = SIFT()
        try:
            sift.detect_and_extract(img)
        except (RuntimeError, IndexError):  # no features (blank / flat) or too small an image
            pass
        else:
            if len(sift.descriptors):
                return _normalise(sift.descriptors.astype(np.float64))
    return dense_descriptors(img, cfg.grid_step_px, cfg.patch_px)


def nearest_words(desc: np.ndarray, vocabulary: np.ndarray) -> np.ndarray:
    """``(N,)`` int64 index of the nearest (Euclidean) vocabulary row of each descriptor.

    desc : ``(N, 128)`` float. vocabulary : ``(K, 128)`` float (k-means centres)."""
    desc = np.asarray(desc, np.float64)
    d2 = (vocabulary**2).sum(1)[None, :] - 2.0 * desc @ vocabulary.T
    return d2.argmin(axis=1).astype(np.int64)


def word_histogram(words: np.ndarray, vocabulary_size: int) -> np.ndarray:
    """``(K,)`` L2-normalised counts of the visual-word ids ``words (N,)`` (zeros if N = 0)."""
    hist = np.bincount(words, minlength=vocabulary_size).astype(np.float64)
    return hist / max(np.linalg.norm(hist), 1e-12)


class BagOfVisualWords:
    """Bag-of-visual-words classifier: ``fit(images, labels)``, ``predict(images)``.

    images : sequence of ``(H, W)`` grey images (uint8 or float in [0, 1]) or a ``(N, H, W)``
    array; labels : ``(N,)`` int. The vocabulary ``(K, 128)`` is ``cfg.vocabulary_size``
    MiniBatchKMeans centres (seeded); the classifier a ``LinearSVC`` on the word histograms,
    kept as arrays (``learn.classical.LinearSvm``) so that ``to_arrays`` / ``from_arrays`` save
    and restore the exact model without pickle.
    """

    def __init__(self, cfg: BovwConfig | None = None) -> None:
        self.cfg = cfg or BovwConfig()
        self.vocabulary: np.ndarray | None = None
        self.svm: LinearSvm | None = None

    def fit(self, images: Images, labels: np.ndarray) -> BagOfVisualWords:
        """Learn the vocabulary from all descriptors of ``images``, then the SVM."""
        per_image = [image_descriptors(img, self.cfg) for img in images]
        stacked = np.concatenate(per_image)
        if len(stacked) < self.cfg.vocabulary_size:
            raise DataError(
                f"BoVW: {len(stacked)} descriptors for {self.cfg.vocabulary_size} words; "
                "give more images or a smaller BovwConfig.vocabulary_size"
            )
        kmeans = MiniBatchKMeans(
            self.cfg.vocabulary_size,
            batch_size=self.cfg.kmeans_batch_size,
            n_init=3,
            random_state=self.cfg.seed,
        ).fit(stacked)
        self.vocabulary = np.asarray(kmeans.cluster_centers_, np.float64)
        svc = LinearSVC(C=self.cfg.svm_c, random_state=self.cfg.seed)
        self.svm = LinearSvm.from_sklearn(svc.fit(self._encode(per_image), np.asarray(labels)))
        return self

    def _encode(self, per_image: list[np.ndarray]) -> np.ndarray:
        """``(N, K)`` word histograms of per-image descriptor arrays."""
        k = len(self.vocabulary)
        return np.stack([word_histogram(nearest_words(d, self.vocabulary), k) for d in per_image])

    def transform(self, images: Images) -> np.ndarray:
        """``(N, K)`` L2-normalised visual-word histograms."""
        if self.vocabulary is None or self.svm is None:
            raise DataError("BagOfVisualWords: call fit() before transform() / predict()")
        return self._encode([image_descriptors(img, self.cfg) for img in images])

    def decision_function(self, images: Images) -> np.ndarray:
        """SVM scores: ``(N,)`` for two classes, ``(N, C)`` otherwise."""
        return self.svm_or_fail().decision_function(self.transform(images))

    def predict(self, images: Images) -> np.ndarray:
        """``(N,)`` predicted labels."""
        return self.svm_or_fail().predict(self.transform(images))

    def svm_or_fail(self) -> LinearSvm:
        """The fitted SVM (DataError before ``fit``)."""
        if self.svm is None:
            raise DataError("BagOfVisualWords: call fit() before transform() / predict()")
        return self.svm

    def to_arrays(self) -> tuple[dict, dict[str, np.ndarray]]:
        """(configuration dict, arrays: ``vocabulary`` (K, 128) and the SVM's) of a fitted model."""
        return asdict(self.cfg), {"vocabulary": self.vocabulary, **self.svm_or_fail().arrays()}

    @classmethod
    def from_arrays(cls, meta: dict, arrays: dict[str, np.ndarray]) -> BagOfVisualWords:
        """The model :meth:`to_arrays` described (``meta["config"]``: BovwConfig fields)."""
        model = cls(from_dict(BovwConfig, meta["config"]))
        model.vocabulary = np.asarray(arrays["vocabulary"], np.float64)
        model.svm = LinearSvm.from_arrays(arrays)
        return model
