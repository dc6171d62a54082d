"""Held-out or not: a model scored on another dataset than the one it was trained on.

Two handskin datasets generated with one seed draw their subjects and object instances from one
pool (``s0000``.. for any ``n``), but each splits them its own way (the greedy 70/30 split
balances sample counts, which depend on ``n``). A model trained on one and tested on the other
can therefore be tested on people it was trained on. :func:`shared_groups` finds them.

    shared = shared_groups("data/forearm", "data/forearm3x")
    shared["test_samples"]   # test samples of forearm3x whose subject / instance forearm trained on
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from learn.folder import is_dataset
from tactile.dataset.reader import DatasetReader
from tactile.errors import DataError

#: Manifest fields that fix the subject and instance pools (seed, part, pool sizes).
POOL_KEYS = ("seed", "part", "n_subjects", "instances_per_kind")


def _pool(folder: Path) -> tuple | None:
    """The pool identity of a generated dataset, None for one without a manifest."""
    from tactile.dataset.manifest import read_manifest

    try:
        manifest = read_manifest(folder)
    except DataError:
        return None
    config = manifest.get("config") or {}
    return tuple(manifest.get(k, config.get(k)) for k in POOL_KEYS)


def _folder(path: str | Path) -> Path:
    path = Path(path)
    return path.parent if path.suffix == ".h5" else path


def _ids(reader: DatasetReader, field: str) -> np.ndarray:
    """(S,) int ids of a field, all -1 when the dataset does not have it."""
    if field not in reader.fields:
        return np.full(len(reader), -1, dtype=np.int64)
    return np.asarray(reader[field][:], dtype=np.int64)


def shared_groups(train_data: str | Path, test_data: str | Path) -> dict | None:
    """Subjects and object instances of ``train_data``'s train split that are in ``test_data``'s
    test split, when the two are different datasets drawn from one pool (manifests with the same
    seed, part, subject count and instances per kind); None when that cannot happen (the same
    folder: its split is disjoint by construction) or cannot be told (a folder missing, or one
    without a manifest, e.g. ingested real data).

    Returns ``{"subjects": [...], "instances": [...], "test_samples": int, "n_test": int}``: the
    shared ids and how many of the ``n_test`` test samples carry one.
    """
    a, b = _folder(train_data), _folder(test_data)
    if not is_dataset(a) or not is_dataset(b):
        return None
    if a.resolve() == b.resolve():
        return None
    pool = _pool(a)
    if pool is None or pool != _pool(b):
        return None
    with DatasetReader(a) as ra, DatasetReader(b) as rb:
        train, test = ra.splits["train"], rb.splits["test"]
        seen = [set(_ids(ra, f)[train].tolist()) - {-1} for f in ("subject_id", "instance_id")]
        ids = [_ids(rb, f)[test] for f in ("subject_id", "instance_id")]
    hit = np.zeros(len(test), dtype=bool)
    shared = []
    for known, mine in zip(seen, ids, strict=True):
        both = sorted(known & (set(mine.tolist()) - {-1}))
        shared.append(both)
        hit |= np.isin(mine, both)
    return {"subjects": shared[0], "instances": shared[1], "test_samples": int(hit.sum()),
            "n_test": len(test)}  # fmt: skip


def leakage_note(shared: dict | None) -> str | None:
    """The report's warning for :func:`shared_groups`' result, None when nothing is shared."""
    if not shared or not shared["test_samples"]:
        return None
    return (f"**Not held out**: {shared['test_samples']} of the {shared['n_test']} test samples "
            f"come from {len(shared['subjects'])} subjects and {len(shared['instances'])} object "
            "instances this model was trained on (the training dataset shares this one's "
            "subject pool but not its split). Fix: score it on its own dataset's test split.")
