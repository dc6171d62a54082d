"""A copy of a dataset whose test split shares people with its training split (a diagnostic).

    python docs/resplit_by_sample.py data/paper data/paper_bysample [--seed 0] \
        [--common data/paper_common]

handskin splits every dataset by subject and object instance: no person and no object is on
both sides, so a test score says how a model does on people it has never seen. A split by
sample, as a random 70 / 30 cut of the recordings would be, lets a person's other presses
into training. This writes a copy of DATASET at OUT whose test split holds as many hands and
as many non-hands as DATASET's, drawn at random (``numpy.random.default_rng(seed)``) from
all samples, whoever pressed; everything else is the same bytes. Train and score on it with
the usual commands to see how much of a test score's gap to the training images is the new
people. The copy's test people are not held out: never report its scores as held-out ones
(`handskin train` warns and `handskin evaluate` flags them).

The two test splits differ, so their scores differ by the luck of the draw too. ``--common``
also writes a copy of DATASET whose test split is the samples in both test splits (about 30 %
of each): scored there, a model trained on DATASET meets people it has never seen and one
trained on the by-sample copy people it has (`handskin evaluate` flags that one), on the same
samples, so the report's paired comparisons apply.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import h5py
import numpy as np


def _write_splits(dst: Path, train: np.ndarray, test: np.ndarray) -> None:
    with h5py.File(dst / "dataset.h5", "r+") as f:
        for name, idx in (("train", train), ("test", test)):
            del f[f"splits/{name}"]
            f[f"splits/{name}"] = np.sort(idx).astype(np.int64)


def _check(src: Path, dst: Path) -> None:
    if dst.exists():
        raise SystemExit(f"{dst} exists. Fix: give a new folder, or delete it")
    if not (src / "dataset.h5").is_file():
        raise SystemExit(f"no dataset.h5 in {src}. Fix: give a folder from handskin generate")


def resplit_by_sample(src: Path, dst: Path, seed: int = 0) -> dict[str, object]:
    """Copy dataset ``src`` to ``dst`` (which must not exist) with a test split of the same
    size per class, drawn by sample; returns counts: per class, test samples and how many of
    the new test samples' subjects (hands) also press in its training split."""
    _check(src, dst)
    with h5py.File(src / "dataset.h5", "r") as f:
        hand = np.asarray(f["samples/is_hand"][:]).astype(bool)
        subject = np.asarray(f["samples/subject_id"][:])
        old_test = np.asarray(f["splits/test"][:])
    rng = np.random.default_rng(seed)
    test = np.sort(
        np.concatenate(
            [
                rng.choice(
                    np.flatnonzero(hand == c), int((hand[old_test] == c).sum()), replace=False
                )
                for c in (False, True)
            ]
        )
    )
    train = np.setdiff1d(np.arange(len(hand)), test)
    shutil.copytree(src, dst)
    _write_splits(dst, train, test)
    seen = set(subject[train][hand[train]].tolist())
    test_hands = test[hand[test]]
    return {
        "test_hands": len(test_hands),
        "test_non_hands": int((~hand[test]).sum()),
        "test_hands_of_training_people": int(sum(s in seen for s in subject[test_hands])),
        "seed": seed,
    }


def common_copy(src: Path, other: Path, dst: Path) -> int:
    """Copy dataset ``src`` to ``dst`` (which must not exist) with the samples in both ``src``'s
    and ``other``'s test splits as its test split (the rest as train); returns their count."""
    _check(src, dst)
    with h5py.File(src / "dataset.h5", "r") as f, h5py.File(other / "dataset.h5", "r") as g:
        n = len(f["samples/is_hand"])
        common = np.intersect1d(f["splits/test"][:], g["splits/test"][:])
    shutil.copytree(src, dst)
    _write_splits(dst, np.setdiff1d(np.arange(n), common), common)
    return len(common)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dataset", type=Path, help="a handskin dataset folder")
    p.add_argument("out", type=Path, help="the copy's folder (must not exist)")
    p.add_argument("--seed", type=int, default=0, help="seed of the draw (no unit)")
    p.add_argument(
        "--common",
        type=Path,
        help="also write this copy of DATASET, tested on the "
        "samples both test splits hold (must not exist)",
    )
    a = p.parse_args()
    if a.common is not None:
        _check(a.dataset, a.common)
    counts = resplit_by_sample(a.dataset, a.out, a.seed)
    if a.common is not None:
        counts["common_test_samples"] = common_copy(a.dataset, a.out, a.common)
    print(json.dumps(counts))


if __name__ == "__main__":
    main()
