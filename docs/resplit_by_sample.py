"""A copy of a dataset whose test split shares people with its training split (a diagnostic).

    python docs/resplit_by_sample.py data/paper data/paper_bysample [--seed 0]

handskin splits every dataset by subject and object instance: no person and no object is on
both sides, so a test score says how a model does on people it has never seen. A split by
sample, as a random 70 / 30 cut of the recordings would be, lets a person's other presses
into training. This writes a copy of DATASET at OUT whose test split holds as many hands and
as many non-hands as DATASET's, drawn at random (``numpy.random.default_rng(seed)``) from
all samples, whoever pressed; everything else is the same bytes. Train and score on it with
the usual commands to see how much of a test score's gap to the training images is the new
people. The copy's test people are not held out: never report its scores as held-out ones.
"""

from __future__ import annotations

import argparse
import json
import shutil
from pathlib import Path

import h5py
import numpy as np


def resplit_by_sample(src: Path, dst: Path, seed: int = 0) -> dict[str, object]:
    """Copy dataset ``src`` to ``dst`` (which must not exist) with a test split of the same
    size per class, drawn by sample; returns counts: per class, test samples and how many of
    the new test samples' subjects (hands) also press in its training split."""
    if dst.exists():
        raise SystemExit(f"{dst} exists. Fix: give a new folder, or delete it")
    if not (src / "dataset.h5").is_file():
        raise SystemExit(f"no dataset.h5 in {src}. Fix: give a folder from handskin generate")
    shutil.copytree(src, dst)
    rng = np.random.default_rng(seed)
    with h5py.File(dst / "dataset.h5", "r+") as f:
        hand = np.asarray(f["samples/is_hand"][:]).astype(bool)
        subject = np.asarray(f["samples/subject_id"][:])
        old_test = np.asarray(f["splits/test"][:])
        test = np.sort(np.concatenate([
            rng.choice(np.flatnonzero(hand == c), int((hand[old_test] == c).sum()), replace=False)
            for c in (False, True)]))  # fmt: skip
        train = np.setdiff1d(np.arange(len(hand)), test)
        for name, idx in (("train", train), ("test", test)):
            del f[f"splits/{name}"]
            f[f"splits/{name}"] = idx.astype(np.int64)
    seen = set(subject[train][hand[train]].tolist())
    test_hands = test[hand[test]]
    return {"test_hands": len(test_hands), "test_non_hands": int((~hand[test]).sum()),
            "test_hands_of_training_people": int(sum(s in seen for s in subject[test_hands])),
            "seed": seed}  # fmt: skip


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("dataset", type=Path, help="a handskin dataset folder")
    p.add_argument("out", type=Path, help="the copy's folder (must not exist)")
    p.add_argument("--seed", type=int, default=0, help="seed of the draw (no unit)")
    a = p.parse_args()
    print(json.dumps(resplit_by_sample(a.dataset, a.out, a.seed)))


if __name__ == "__main__":
    main()
