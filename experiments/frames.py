"""Test frames of the robustness experiments (torch-free): raw readings back to the pressures a
dataset's images were made from, a split held in memory, and network inputs made as in training.

    test = load_frames("data/forearm", "test", n_classify=None, n_segment=200, seed=0)
    images = test.tmap.image(test.pressure_pa[:64])   # (64, H, W) uint8, the stored pipeline
    x = net_inputs(images, (68, 100), "classify")     # (64, 1, 68, 100) float32 in [0, 1]

Pressures come from ``DatasetReader.pressure_from_raw`` with the frames' ``time_s``: the
generator's own readout (baseline, drift, 3-sigma noise floor, nominal gain), so frames at zero
corruption give the stored images.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from learn.inputs import net_input
from tactile.dataset.reader import DatasetReader
from tactile.errors import DataError
from tactile.geometry.layout import TaxelLayout
from tactile.images.labels import label_image
from tactile.images.tactile_map import TactileMap

#: First spawn-key element of each random stream drawn from the one --seed (kept disjoint).
KEY_SUBSET, KEY_SPOTS, KEY_REMOVAL, KEY_POOL, KEY_COPIES = 1, 2, 3, 4, 5
CHUNK = 128  # frames imaged at once (a 229 x 383 float64 batch of 128 is 90 MB)


def stream(seed: int, *key: int) -> np.random.Generator:
    """The generator of one random stream: ``SeedSequence(seed, spawn_key=key)``."""
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=tuple(map(int, key))))


@dataclass(frozen=True, eq=False)
class Frames:
    """Frames of one split in memory; rows in split order.

    tmap, layout : the dataset's map and layout (N taxels, (H, W) images).
    sample_ids : (S,) int64 dataset sample of each row. pressure_pa : (S, N) float64, Pa.
    is_hand : (S,) int64, 0/1. taxel_label : (S, N) uint8, 0..6.
    classify : (C,) int64 rows used for classification. segment : (K,) int64 rows (hand
    samples) used for segmentation. label_image : (K, H, W) uint8, their ground truth
    regenerated at zero corruption. n_split : samples in the whole split.
    """

    tmap: TactileMap
    layout: TaxelLayout
    sample_ids: np.ndarray
    pressure_pa: np.ndarray
    is_hand: np.ndarray
    taxel_label: np.ndarray
    classify: np.ndarray
    segment: np.ndarray
    label_image: np.ndarray
    n_split: int


def _pick(n_total: int, n: int | None, rng: np.random.Generator) -> np.ndarray:
    """Sorted positions of a seeded subset of size ``n`` (all when None or n >= n_total)."""
    if n is None or n >= n_total:
        return np.arange(n_total)
    return np.sort(rng.choice(n_total, size=n, replace=False))


def load_frames(
    path: str | Path,
    split: str = "test",
    *,
    n_classify: int | None = None,
    n_segment: int = 0,
    seed: int = 0,
) -> Frames:
    """Read a split's frames: pressures from raw readings, labels, and the chosen subsets.

    n_classify : samples classified (seeded subset; None = all). n_segment : hand samples
    segmented (seeded subset, at most all; 0 = none). Subsets come from
    ``stream(seed, KEY_SUBSET)``.
    """
    reader = DatasetReader(path)
    need = ("is_hand", "taxel_label")[: 1 + bool(n_segment)]
    missing = [f for f in need if f not in reader.fields]
    if missing:
        raise DataError(
            f"{reader.path} has no {missing}; the robustness tests need them. Fix: a dataset "
            "with hand labels (generated, or ingested with --labels)"
        )
    with reader:
        ids = np.asarray(reader.splits.get(split, []), dtype=np.int64)
        if len(ids) == 0:
            raise DataError(f"{reader.path}: the {split} split is empty. Fix: re-merge the dataset")
        rng = stream(seed, KEY_SUBSET)
        is_hand = reader.is_hand[:].astype(np.int64)[ids]
        clf = _pick(len(ids), n_classify, rng)
        hands = np.flatnonzero(is_hand == 1)
        if n_segment and len(hands) == 0:
            raise DataError(f"{reader.path}: no hand sample in the {split} split to segment")
        seg = hands[_pick(len(hands), n_segment, rng)] if n_segment else hands[:0]
        rows = np.union1d(clf, seg)
        p, labels = read_rows(reader, ids[rows])
    pos = {r: i for i, r in enumerate(rows)}
    seg_rows = np.array([pos[r] for r in seg], dtype=np.int64)
    truth = label_images(reader.map, p[seg_rows], labels[seg_rows])
    clf_rows = np.array([pos[r] for r in clf], dtype=np.int64)
    head = (reader.map, reader.layout, ids[rows], p, is_hand[rows], labels)
    return Frames(*head, clf_rows, seg_rows, truth, len(ids))


def read_rows(reader: DatasetReader, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(pressures (S, N) Pa, taxel labels (S, N) uint8) of dataset samples ``ids`` (any
    order); labels are 0 in a dataset without them."""
    order = np.argsort(ids)
    sorted_ids, back = ids[order], np.argsort(order)
    raw = reader.raw[sorted_ids][back]
    time_s = reader.time_s[sorted_ids][back] if "time_s" in reader.fields else None
    labels = np.zeros(raw.shape, np.uint8)
    if "taxel_label" in reader.fields:
        labels = reader.taxel_label[sorted_ids][back].astype(np.uint8)
    return reader.pressure_from_raw(raw, time_s), labels


def images(tmap: TactileMap, p: np.ndarray) -> np.ndarray:
    """Tactile images (B, H, W) uint8 of frames p (B, N) Pa, imaged ``CHUNK`` at a time."""
    parts = [tmap.image(p[s : s + CHUNK]) for s in range(0, len(p), CHUNK)]
    return np.concatenate(parts) if parts else np.zeros((0, *tmap.shape), np.uint8)


def label_images(tmap: TactileMap, p: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Label images (B, H, W) uint8 of frames p (B, N) Pa with taxel classes (B, N)."""
    out = np.zeros((len(p), *tmap.shape), dtype=np.uint8)
    for i, image in enumerate(images(tmap, p)):
        out[i] = label_image(tmap, p[i], labels[i], image=image)
    return out


def net_inputs(
    images_u8: np.ndarray, size: tuple[int, int], task: str, canvas: tuple[int, int] | None = None
) -> np.ndarray:
    """Network inputs (B, 1, h, w) float32 in [0, 1] of ``task``'s networks from images
    (B, H, W) uint8, made as training makes them (``learn.inputs.net_input``; ``canvas``:
    (H', W') map pixels of the model's input canvas, or None)."""
    if not len(images_u8):
        return np.zeros((0, 1, 0, 0), np.float32)
    return net_input(np.asarray(images_u8, np.uint8), tuple(size), task, canvas)[:, None]
