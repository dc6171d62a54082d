"""Train/test split by groups: no subject and no object instance on both sides, both classes
on both sides, deterministic from a seed.

Samples are linked when they share a subject (``subject_id >= 0``) or an instance
(``instance_id >= 0``); the connected components of these links are the units that are split, so
subjects and instances are disjoint between train and test even if a sample carries both. A
sample with neither id is its own unit. Units are stratified by class (``is_hand``, majority
vote). Two methods (``METHODS``):

- ``"greedy"`` (the default): within each class the units are shuffled by
  ``np.random.default_rng(seed)`` and assigned greedily to train until the class's train
  fraction is closest to the target. The fractions are close to exact, but which units land
  in test depends on every unit's sample count, so two datasets of one seed with other
  rejection counts (another part) or another ``n`` hold out other people.
- ``"keyed"``: a unit's side depends only on the seed and its key (its smallest subject id, or
  else its smallest instance id, or else the sample's index): it goes to train when
  ``U(SeedSequence([seed, stream, kind, id])) < train_fraction``. Datasets of one seed, on any
  part and of any size, then hold out the same subjects and instances, so their test scores are
  comparable sample by sample; the achieved fractions scatter around the target by the
  binomial spread of the unit count (about ±5 points for 90 subjects).

With either method, when a class has at least two units both sides receive one (for
``"keyed"`` by moving the unit whose draw lies nearest the threshold, the one exception to its
stability).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from tactile.errors import DataError

TRAIN_FRACTION = 0.7  # the paper's 70/30 split
METHODS = ("greedy", "keyed")


@dataclass(frozen=True)
class Split:
    """train, test : (K,) int64 sorted sample indices. report : achieved fractions and counts."""

    train: np.ndarray
    test: np.ndarray
    report: dict[str, object]


def _ids(values: np.ndarray | None, n: int, name: str) -> np.ndarray:
    if values is None:
        return np.full((n, 1), -1, dtype=np.int64)
    arr = np.asarray(values).astype(np.int64)
    if arr.ndim not in (1, 2) or len(arr) != n:
        raise DataError(f"{name} has shape {arr.shape}; expected ({n},) or ({n}, K) ids")
    return _columns(arr)


def _columns(ids: np.ndarray) -> np.ndarray:
    """(S,) or (S, K) ids as (S, K) (K = 1 for one id per sample)."""
    ids = np.asarray(ids)
    return ids[:, None] if ids.ndim == 1 else ids


def units(subject_id: np.ndarray, instance_id: np.ndarray) -> np.ndarray:
    """Unit (connected component) of each sample: (S,) int64. Ids are (S,) or (S, K) int (K ids
    per sample: a sample pressed by several contactors), -1 = none."""
    subject_id, instance_id = _columns(subject_id), _columns(instance_id)
    n = len(subject_id)
    keys = []  # (sample, key node) edges; key nodes are numbered after the samples
    offset = n
    for ids in (subject_id, instance_id):
        sample, slot = np.nonzero(ids >= 0)
        _, key = np.unique(ids[sample, slot], return_inverse=True)
        keys.append((sample, key + offset))
        offset += int(key.max(initial=-1)) + 1
    rows = np.concatenate([k[0] for k in keys])
    cols = np.concatenate([k[1] for k in keys])
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(offset, offset))
    return connected_components(graph, directed=False)[1][:n].astype(np.int64)


def unit_keys(unit: np.ndarray, subject_id: np.ndarray, instance_id: np.ndarray) -> np.ndarray:
    """(U, 2) int64 key of each unit: (0, smallest subject id), else (1, smallest instance id),
    else (2, index of its one sample). ``unit`` is :func:`units`' output, ids (S,) or (S, K)."""
    n_units = int(unit.max(initial=-1)) + 1
    keys = np.zeros((n_units, 2), np.int64)
    big = np.iinfo(np.int64).max
    first = np.full(n_units, big)
    np.minimum.at(first, unit, np.arange(len(unit), dtype=np.int64))
    keys[:, 0], keys[:, 1] = 2, first
    for kind, ids in ((1, instance_id), (0, subject_id)):  # subjects last: they win
        ids = _columns(ids)
        low = np.full(n_units, big)
        sample, slot = np.nonzero(ids >= 0)
        np.minimum.at(low, unit[sample], ids[sample, slot].astype(np.int64))
        found = low < big
        keys[found, 0], keys[found, 1] = kind, low[found]
    return keys


def keyed_draws(keys: np.ndarray, seed: int, stream: int = 0) -> np.ndarray:
    """(U,) float64 in [0, 1): one uniform draw per unit key (U, 2) from
    ``SeedSequence([seed, stream, kind, id])``; the same key gives the same draw in any dataset."""
    return np.array(
        [np.random.default_rng([seed, stream, int(k), int(i)]).random() for k, i in keys]
    )


def _assign_keyed(draws: np.ndarray, fraction: float) -> np.ndarray:
    """True for units whose draw is below ``fraction``; both sides non-empty for >= 2 units."""
    train = draws < fraction
    if len(draws) >= 2 and not train.any():
        train[np.argmin(draws)] = True
    if len(draws) >= 2 and train.all():
        train[np.argmax(draws)] = False
    return train


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
    method: str = "greedy",
    stream: int = 0,
) -> Split:
    """Group-disjoint, class-stratified train/test split of S samples.

    is_hand : (S,) 0/1, or None (one stratum). subject_id, instance_id : (S,) or (S, K) int
    (K per sample when several contactors press), -1 = none, or None. train_fraction : float
    in (0, 1). seed : int. method : one of ``METHODS`` (module docstring). stream : int,
    ``"keyed"`` only — another stream gives independent draws from the same seed (a validation
    split inside a keyed train split). Returns a :class:`Split`.
    """
    if not 0.0 < train_fraction < 1.0:
        raise DataError(f"train_fraction must be in (0, 1), got {train_fraction}")
    if method not in METHODS:
        raise DataError(f"split method {method!r} unknown; choose one of {', '.join(METHODS)}")
    n = next((len(a) for a in (is_hand, subject_id, instance_id) if a is not None), 0)
    cls = np.zeros(n, np.int64) if is_hand is None else np.asarray(is_hand).astype(np.int64)
    subject, instance = _ids(subject_id, n, "subject_id"), _ids(instance_id, n, "instance_id")
    unit = units(subject, instance)
    n_units = int(unit.max(initial=-1)) + 1
    counts = np.zeros((n_units, 2), np.int64)
    np.add.at(counts, (unit, cls.clip(0, 1)), 1)
    unit_cls = (counts[:, 1] > counts[:, 0]).astype(np.int64)
    rng = np.random.default_rng(seed)
    draws = (
        keyed_draws(unit_keys(unit, subject, instance), seed, stream) if method == "keyed" else None
    )
    in_train = np.zeros(n_units, dtype=bool)
    for c in (0, 1):
        members = np.flatnonzero(unit_cls == c)
        in_train[members] = (
            _assign(counts[members].sum(axis=1), train_fraction, rng)
            if draws is None
            else _assign_keyed(draws[members], train_fraction)
        )
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
