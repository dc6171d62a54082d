"""Train/test split by groups: no subject and no object instance on both sides, both classes
on both sides, deterministic from a seed.

Samples are linked when they share a subject (``subject_id >= 0``) or an instance
(``instance_id >= 0``); the connected components of these links are the units that are split, so
subjects and instances are disjoint between train and test even if a sample carries both. A
sample with neither id is its own unit. Units are stratified by class (``is_hand``, majority
vote): within each class they are shuffled by ``np.random.default_rng(seed)`` and assigned greedily
to train until the class's train fraction is closest to the target; when a class has at least two
units both sides receive one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from tactile.errors import DataError

TRAIN_FRACTION = 0.7  # the paper's 70/30 split


@dataclass(frozen=True)
class Split:
    """train, test : (K,) int64 sorted sample indices. report : achieved fractions and counts."""

    train: np.ndarray
    test: np.ndarray
    report: dict[str, object]


def _ids(values: np.ndarray | None, n: int, name: str) -> np.ndarray:
    if values is None:
        return np.full(n, -1, dtype=np.int64)
    arr = np.asarray(values).astype(np.int64)
    if arr.shape != (n,):
        raise DataError(f"{name} has shape {arr.shape}; expected ({n},) like the other ids")
    return arr


def units(subject_id: np.ndarray, instance_id: np.ndarray) -> np.ndarray:
    """Unit (connected component) of each sample: (S,) int64. Ids are (S,) int, -1 = none."""
    n = len(subject_id)
    keys = []  # (sample, key node) edges; key nodes are numbered after the samples
    offset = n
    for ids in (subject_id, instance_id):
        has = np.flatnonzero(ids >= 0)
        _, key = np.unique(ids[has], return_inverse=True)
        keys.append((has, key + offset))
        offset += int(key.max(initial=-1)) + 1
    rows = np.concatenate([k[0] for k in keys])
    cols = np.concatenate([k[1] for k in keys])
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(offset, offset))
    return connected_components(graph, directed=False)[1][:n].astype(np.int64)


def _assign(sizes: np.ndarray, fraction: float, rng: np.random.Generator) -> np.ndarray:
    """Greedy: True for units put in train, in a random order, closest to ``fraction``."""
    order = rng.permutation(len(sizes))
    target, taken = fraction * sizes.sum(), 0
    train = np.zeros(len(sizes), dtype=bool)
    for u in order:
        if abs(taken + sizes[u] - target) <= abs(taken - target):
            train[u], taken = True, taken + sizes[u]
    if len(sizes) >= 2 and not train.any():
        train[order[0]] = True
    if len(sizes) >= 2 and train.all():
        train[order[-1]] = False
    return train


def split_indices(
    is_hand: np.ndarray | None,
    subject_id: np.ndarray | None = None,
    instance_id: np.ndarray | None = None,
    *,
    train_fraction: float = TRAIN_FRACTION,
    seed: int = 0,
) -> Split:
    """Group-disjoint, class-stratified train/test split of S samples.

    is_hand : (S,) 0/1, or None (one stratum). subject_id, instance_id : (S,) int, -1 = none, or
    None. train_fraction : float in (0, 1). seed : int. Returns a :class:`Split`.
    """
    if not 0.0 < train_fraction < 1.0:
        raise DataError(f"train_fraction must be in (0, 1), got {train_fraction}")
    n = next((len(a) for a in (is_hand, subject_id, instance_id) if a is not None), 0)
    cls = np.zeros(n, np.int64) if is_hand is None else np.asarray(is_hand).astype(np.int64)
    unit = units(_ids(subject_id, n, "subject_id"), _ids(instance_id, n, "instance_id"))
    n_units = int(unit.max(initial=-1)) + 1
    counts = np.zeros((n_units, 2), np.int64)
    np.add.at(counts, (unit, cls.clip(0, 1)), 1)
    unit_cls = (counts[:, 1] > counts[:, 0]).astype(np.int64)
    rng = np.random.default_rng(seed)
    in_train = np.zeros(n_units, dtype=bool)
    for c in (0, 1):
        members = np.flatnonzero(unit_cls == c)
        in_train[members] = _assign(counts[members].sum(axis=1), train_fraction, rng)
    train_mask = in_train[unit]
    train, test = np.flatnonzero(train_mask), np.flatnonzero(~train_mask)
    return Split(train, test, split_report(cls if is_hand is not None else None, train_mask))


def split_report(cls: np.ndarray | None, train_mask: np.ndarray) -> dict[str, object]:
    """Achieved train fraction overall and per class, and the counts of each side."""
    n = len(train_mask)
    report: dict[str, object] = {
        "n_train": int(train_mask.sum()),
        "n_test": int(n - train_mask.sum()),
        "train_fraction": float(train_mask.mean()) if n else 0.0,
    }
    if cls is not None:
        for c, name in ((1, "hand"), (0, "non_hand")):
            mine = cls == c
            report[f"train_fraction_{name}"] = float(train_mask[mine].mean()) if mine.any() else 0.0
            report[f"n_test_{name}"] = int((mine & ~train_mask).sum())
    return report
