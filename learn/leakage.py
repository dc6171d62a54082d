"""Held-out or not: a model scored on another dataset than the one it was trained on.

Two handskin datasets generated with one seed draw their subjects from one pool (``s0000``.. for
any ``n`` and any part: a subject's hand depends on the seed and its id only), and the
generator's object and body-part instances depend on their id alone (`sim.primitives.
instance_rng`), so every generated dataset shares one instance pool whatever its seed or part.
Each dataset splits them its own way (the default greedy 70/30 split balances sample counts,
which depend on ``n`` and on the part's rejections; ``--split keyed`` fixes a subject's side by
seed and id), so a model trained on one and tested on another can be tested on people or
objects it was trained on. :func:`shared_groups` finds them.

    shared = shared_groups("data/forearm", "data/forearm3x")
    shared["test_samples"]   # test samples of forearm3x whose subject / instance forearm trained on
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from learn.folder import is_dataset
from tactile.dataset.reader import DatasetReader
from tactile.errors import DataError

#: Manifest fields that fix the subject pool (the seed and the pool size; not the part).
POOL_KEYS = ("seed", "n_subjects")


def _pools(folder: Path) -> tuple[tuple, tuple] | None:
    """(subject pool, instance pool) identities of a dataset, None without a manifest. The
    generator's instances (configs with ``instances_per_kind``) are one global pool; other
    writers' instance ids are taken to be as local as their subjects."""
    from tactile.dataset.manifest import read_manifest

    try:
        manifest = read_manifest(folder)
    except DataError:
        return None
    config = manifest.get("config") or {}
    subjects = tuple(manifest.get(k, config.get(k)) for k in POOL_KEYS)
    return subjects, (("generator",) if "instances_per_kind" in config else subjects)


def _folder(path: str | Path) -> Path:
    path = Path(path)
    return path.parent if path.suffix == ".h5" else path


def _ids(reader: DatasetReader, field: str) -> np.ndarray:
    """(S,) int ids of a field, all -1 when the dataset does not have it."""
    if field not in reader.fields:
        return np.full(len(reader), -1, dtype=np.int64)
    return np.asarray(reader[field][:], dtype=np.int64)


def _seen(a: Path, b: Path) -> list[set] | None:
    """(subject ids, instance ids) of dataset ``a``'s train split that could be in dataset ``b``
    (an empty set for a pool they do not share); None when they can share nothing."""
    if not is_dataset(a) or not is_dataset(b) or a.resolve() == b.resolve():
        return None
    pools_a, pools_b = _pools(a), _pools(b)
    if pools_a is None or pools_b is None:
        return None
    same = [pa == pb for pa, pb in zip(pools_a, pools_b, strict=True)]
    if not any(same):
        return None
    with DatasetReader(a) as ra:
        train = ra.splits["train"]
        return [
            set(_ids(ra, f)[train].tolist()) - {-1} if ok else set()
            for f, ok in zip(("subject_id", "instance_id"), same, strict=True)
        ]


def shared_groups(
    train_data: str | Path | Sequence[str | Path],
    test_data: str | Path,
    among: np.ndarray | None = None,
    *,
    own_split: bool = False,
) -> dict | None:
    """Subjects and object instances of ``train_data``'s train split (of each, for several
    datasets: a model's :func:`lineage`) that are in ``test_data``'s test split, when the two are
    different datasets that can share them: subjects when both were drawn from one subject pool
    (the same seed and subject count, any part or size), instances when both come from the
    generator (any seed) or share a subject pool. None when that cannot happen for any of them
    (the same folder, unless ``own_split``: handskin's splits are disjoint by construction;
    other pools) or cannot be told (a folder missing, or one without a manifest, e.g. ingested
    real data).

    ``among``: the dataset indices of the test samples scored (a segmenter's: the hands), by
    default the whole test split. ``own_split``: when ``test_data`` is itself among
    ``train_data``, also check its own split, which a split by sample breaks (handskin's
    splits never share a person; ``docs/resplit_by_sample.py`` makes such a copy on purpose, and
    a split edited by hand may). Returns ``{"subjects": [...], "instances": [...],
    "test_samples": int, "n_test": int, "own_split_samples": int}``: the shared ids, how many
    of the ``n_test`` test samples carry one, and how many share one with ``test_data``'s own
    train split (0 without ``own_split``).
    """
    many = [train_data] if isinstance(train_data, str | Path) else list(train_data)
    b = _folder(test_data)
    seen: list[set] = [set(), set()]  # subject and instance ids trained on, over the datasets
    folders = {_folder(d).resolve(): _folder(d) for d in many}
    own = own_split and is_dataset(b) and b.resolve() in folders
    can_share = own
    for a in folders.values():
        if (found := _seen(a, b)) is not None:
            can_share = True
            seen = [s | f for s, f in zip(seen, found, strict=True)]
    if not can_share:
        return None
    fields = ("subject_id", "instance_id")
    with DatasetReader(b) as rb:
        test = rb.splits["test"] if among is None else np.asarray(among, dtype=np.int64)
        ids = [_ids(rb, f)[test] for f in fields]
        mine_train = [
            set(_ids(rb, f)[rb.splits["train"]].tolist()) - {-1} if own else set() for f in fields
        ]
    hit, own_hit = np.zeros(len(test), dtype=bool), np.zeros(len(test), dtype=bool)
    shared = []
    for known, own_known, mine in zip(seen, mine_train, ids, strict=True):
        both = sorted((known | own_known) & (set(mine.tolist()) - {-1}))
        shared.append(both)
        hit |= np.isin(mine, both)
        own_hit |= np.isin(mine, sorted(own_known))
    return {
        "subjects": shared[0],
        "instances": shared[1],
        "test_samples": int(hit.sum()),
        "n_test": len(test),
        "own_split_samples": int(own_hit.sum()),
    }


def test_hands(data_path: str | Path) -> np.ndarray | None:
    """(K,) int64 dataset indices of the test split's hand samples, the ones a segmenter is
    scored on; None for a folder that is not a handskin dataset."""
    folder = _folder(data_path)
    if not is_dataset(folder):
        return None
    with DatasetReader(folder) as ds:
        test = ds.splits["test"]
        return test[np.asarray(ds.is_hand[:], dtype=bool)[test]]


def leakage_note(shared: dict | None) -> str | None:
    """The report's warning for :func:`shared_groups`' result, None when nothing is shared."""
    if not shared or not shared["test_samples"]:
        return None
    head = (
        f"**Not held out**: {shared['test_samples']} of the {shared['n_test']} test samples "
        f"come from {len(shared['subjects'])} subjects and {len(shared['instances'])} object "
        "instances this model was trained on"
    )
    own = shared.get("own_split_samples", 0)
    if own:
        return (
            f"{head}: this dataset's own train and test splits share them ({own} test "
            "samples), as a split by sample does (a copy from docs/resplit_by_sample.py, or "
            "a split edited by hand). Fix: score it on a dataset split by person, as "
            "handskin generate and ingest split them."
        )
    return (
        f"{head}, or a checkpoint it started from or learned from "
        "(`learn.leakage.lineage`: those training datasets share people or objects "
        "with this one but not its split). Fix: score it on its own dataset's test split, "
        "or generate them with --split keyed and one seed."
    )


def own_split_note(data_path: str | Path, among: np.ndarray | None = None) -> str | None:
    """A warning for ``handskin train`` when ``data_path``'s own test split (``among``: the test
    samples that will be scored, e.g. a segmenter's hands) holds subjects or object instances of
    its train split, as a split by sample does; None for a split by person and for image
    folders."""
    shared = shared_groups([data_path], data_path, among, own_split=True)
    if not shared or not shared["own_split_samples"]:
        return None
    return (
        f"{shared['own_split_samples']} of the {shared['n_test']} test samples of "
        f"{data_path} come from {len(shared['subjects'])} subjects and "
        f"{len(shared['instances'])} object instances of its own train split (a split by "
        "sample, not by person): this run's test scores will not be held out"
    )


def lineage(ckpt: Mapping | None) -> list[dict]:
    """The training-data records (``{"path": ..., ...}``) a model's weights learned from: its
    checkpoint's own ``data`` and its recorded ``ancestry`` (those of the checkpoint it started
    from, ``--init``, and of its teacher, ``distill_from``, recursively). Records without a path
    (data given as tensors) are left out."""
    if not ckpt:
        return []
    records = [ckpt.get("data") or {}, *(ckpt.get("ancestry") or [])]
    return _unique([r for r in records if isinstance(r, Mapping) and r.get("path")])


def ancestry(*sources: str | Path | Mapping | None) -> list[dict]:
    """The ``ancestry`` a new model records: the :func:`lineage` of each checkpoint it starts
    from or learns from (``sources``: paths or checkpoint dicts; None, "random" and model files
    that are not checkpoints are skipped), each dataset once."""
    from learn.checkpoint import load_checkpoint

    records = []
    for src in sources:
        if src is None or src == "random":
            continue
        if not isinstance(src, Mapping):
            if Path(src).suffix != ".pt" or not Path(src).is_file():
                continue
            src = load_checkpoint(src)
        records += lineage(src)
    return _unique(records)


def _unique(records: list[dict]) -> list[dict]:
    """``records`` with each data path once (the first record of it kept)."""
    seen, out = set(), []
    for r in records:
        if str(r["path"]) not in seen:
            seen.add(str(r["path"]))
            out.append(dict(r))
    return out
