"""The shortcut check: how well do simple image statistics alone separate hand from non-hand?

If a logistic regression on five hand-crafted features (contact area, number of blobs, mean
intensity over the contact, bounding-box height and width) already separates the classes, a CNN
could learn that shortcut instead of a hand's shape. The generator's non-hand side must keep this
check's held-out accuracy clearly below a CNN's (target: < 90 %). Works on arrays, so it runs on
any dataset (`load_arrays` reads a dataset file; h5py only).
"""

from __future__ import annotations

from dataclasses import dataclass
from os import PathLike

import h5py
import numpy as np
from skimage.measure import label
from sklearn.linear_model import LogisticRegression
from sklearn.model_selection import GroupShuffleSplit
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from tactile.errors import DataError

FEATURE_NAMES: tuple[str, ...] = (
    "area_px",
    "n_blobs",
    "mean_intensity",
    "bbox_height_px",
    "bbox_width_px",
)
NONHAND_GROUP_OFFSET = 1 << 40  # keeps non-hand instance ids apart from subject ids


def contact_area_px(image: np.ndarray) -> int:
    """Number of contact pixels (value > 0) of one image (H, W)."""
    return int(np.count_nonzero(image > 0))


def blob_count(image: np.ndarray) -> int:
    """Number of 8-connected contact regions (value > 0) of one image (H, W)."""
    return int(label(image > 0, connectivity=2).max())


def mean_intensity(image: np.ndarray) -> float:
    """Mean value over the contact pixels of one image (H, W); 0 when there is no contact."""
    contact = image > 0
    return float(image[contact].mean()) if contact.any() else 0.0


def bbox_px(image: np.ndarray) -> tuple[int, int]:
    """(height, width) in pixels of the box bounding all contact pixels; (0, 0) when none."""
    rows, cols = np.nonzero(image > 0)
    if rows.size == 0:
        return 0, 0
    return int(rows.max() - rows.min() + 1), int(cols.max() - cols.min() + 1)


def image_features(images: np.ndarray) -> np.ndarray:
    """Features (B, 5) float64 in the order of `FEATURE_NAMES` for images (B, H, W)."""
    images = np.asarray(images)
    if images.ndim != 3:
        raise DataError(f"images must be a (B, H, W) stack, got shape {images.shape}")
    return np.array(
        [[contact_area_px(im), blob_count(im), mean_intensity(im), *bbox_px(im)] for im in images],
        dtype=np.float64,
    )


def group_ids(is_hand: np.ndarray, subject_id: np.ndarray, instance_id: np.ndarray) -> np.ndarray:
    """(S,) int64 split groups: the subject for hands, the contactor instance otherwise."""
    hand = np.asarray(is_hand).astype(bool)
    inst = np.asarray(instance_id, dtype=np.int64) + NONHAND_GROUP_OFFSET
    return np.where(hand, np.asarray(subject_id, dtype=np.int64), inst)


def split_by_group(
    groups: np.ndarray,
    test_fraction: float = 0.3,
    seed: int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """(train, test) sample indices (int64) with no group in both; ~``test_fraction`` of the
    groups held out."""
    split = GroupShuffleSplit(n_splits=1, test_size=test_fraction, random_state=seed)
    groups = np.asarray(groups)
    return next(split.split(np.zeros((len(groups), 1)), groups=groups))


@dataclass(frozen=True)
class ShortcutResult:
    """Held-out accuracy of the feature classifier and what it was measured on."""

    accuracy: float  # fraction of held-out samples classified right
    majority_baseline: float  # accuracy of always answering the held-out majority class
    n_train: int
    n_test: int
    coefficients: dict[str, float]  # on standardised features (sign: towards "hand")


def shortcut_check(
    features: np.ndarray,
    is_hand: np.ndarray,
    groups: np.ndarray,
    *,
    test_fraction: float = 0.3,
    seed: int = 0,
) -> ShortcutResult:
    """Logistic regression on ``features`` (S, F) -> ``is_hand`` (S,), held out by ``groups`` (S,)
    (no subject or instance in both train and test). Features standardised on the train part."""
    y = np.asarray(is_hand).astype(int)
    if len(np.unique(y)) < 2 or len(np.unique(groups)) < 2:
        raise DataError("shortcut_check needs both classes and at least two groups")
    train, test = split_by_group(groups, test_fraction, seed)
    model = make_pipeline(StandardScaler(), LogisticRegression(max_iter=1000))
    model.fit(features[train], y[train])
    acc = float((model.predict(features[test]) == y[test]).mean())
    majority = float(max(y[test].mean(), 1 - y[test].mean()))
    names = FEATURE_NAMES if features.shape[1] == len(FEATURE_NAMES) else range(features.shape[1])
    coef = {str(n): float(c) for n, c in zip(names, model[-1].coef_[0], strict=True)}
    return ShortcutResult(acc, majority, len(train), len(test), coef)


def load_arrays(path: str | PathLike[str]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(images (S, H, W) uint8, is_hand (S,), groups (S,)) from a dataset.h5 (schema of
    docs/DESIGN.md)."""
    with h5py.File(path, "r") as f:
        s = f["samples"]
        images, hand = s["image"][...], s["is_hand"][...]
        groups = group_ids(hand, s["subject_id"][...], s["instance_id"][...])
    return images, hand, groups
