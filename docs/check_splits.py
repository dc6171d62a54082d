"""Is the test split harder than the validation split? A classifier on all three splits.

    python docs/check_splits.py CHECKPOINT DATASET

Scores a hand / non-hand checkpoint (eval mode, float32, no flips) on the dataset's training
images (those `handskin train` trained on: the train split minus its validation part), its
validation part and the test split, each with its hand and non-hand accuracy and the hands'
median press force (the dataset's ``force_n``, N). Then, per person in the validation and test
splits, the accuracy on their hands beside their hands' median press force, the lowest
first, and the correlation between the two over those people. The validation part holds out
whole subjects and object instances, as the test split does, but fewer of them, so who lands
in it moves its accuracy: compare the two before trusting a best epoch's validation score.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from learn.breakdown import FORCE_EDGES_N, accuracy_by_bins, bin_labels
from learn.checkpoint import load_checkpoint, model_from_checkpoint
from learn.evaluate import logits_of
from learn.folder import materialize, open_split, validation_split
from tactile.dataset.reader import open_dataset


def split_predictions(ckpt_path: Path, data: Path) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{"train", "val", "test"}: (dataset indices (S,), prediction right (S,) bool)."""
    ckpt = load_checkpoint(ckpt_path)
    model, run = model_from_checkpoint(ckpt)
    model.eval()
    size, canvas, seed = run.model.input_size, run.model.canvas_mm, run.train.seed
    train = open_split(data, "train", run.task, size, None, seed, canvas)
    fit, val = validation_split(train, run.val_fraction, seed)
    parts = {"train": fit, "val": val}
    parts["test"] = open_split(data, "test", run.task, size, None, seed, canvas)
    out = {}
    for name, ds in parts.items():
        if ds is None:
            continue
        t = materialize(ds, name, progress=False)
        with torch.no_grad():
            right = (logits_of(model, t.x).argmax(1) == t.y).numpy()
        out[name] = (np.asarray(ds.indices), right)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("checkpoint", type=Path, help="a classifier's best.pt")
    ap.add_argument("dataset", type=Path, help="the handskin dataset it was trained on")
    args = ap.parse_args()
    torch.set_num_threads(1)
    with open_dataset(args.dataset) as reader:
        hand = reader["is_hand"][:].astype(bool)
        force = reader["force_n"][:]
        subject = reader["subject_id"][:]
    people, by_force = [], []
    print("| split | samples | accuracy % | hands % | non-hands % | hands' median force, N |")
    print("|---|---|---|---|---|---|")
    for name, (idx, right) in split_predictions(args.checkpoint, args.dataset).items():
        h = hand[idx]
        print(
            f"| {name} | {len(idx)} | {100 * right.mean():.2f} | {100 * right[h].mean():.2f} "
            f"| {100 * right[~h].mean():.2f} | {np.median(force[idx][h]):.1f} |"
        )
        bins = accuracy_by_bins(
            right[h].astype(int),
            np.ones(h.sum(), int),
            force[idx][h],
            ["miss", "hand"],
            FORCE_EDGES_N,
        )
        by_force.append(
            f"| {name} | "
            + " | ".join(
                f"{100 * b['per_class']['hand']['accuracy']:.0f} ({b['n']})" if b["n"] else "–"
                for b in bins
            )
            + " |"
        )
        if name != "train":
            for s in np.unique(subject[idx][h]):
                m = h & (subject[idx] == s)
                people.append((right[m].mean(), np.median(force[idx][m]), int(s), name, m.sum()))
    labels = bin_labels(np.zeros(0), FORCE_EDGES_N, "N")[1]
    print("\nHands recognised, % (hands), by press force:\n")
    print("| split | " + " | ".join(labels) + " |\n|---|" + "---|" * len(labels))
    print("\n".join(by_force))
    people.sort()
    acc, med = np.array([p[0] for p in people]), np.array([p[1] for p in people])
    r = (
        f"r = {np.corrcoef(acc, med)[0, 1]:.2f}"
        if len(people) > 1 and acc.std() and med.std()
        else "undefined (too few people, or all alike)"
    )
    print(
        f"\nHeld-out people ({len(people)}): correlation of hand accuracy with median press "
        f"force {r}"
    )
    for lo, hi in ((0, 20), (20, 30), (30, np.inf)):
        group = [p for p in people if lo <= p[1] < hi]
        pooled = sum(p[0] * p[4] for p in group) / max(1, sum(p[4] for p in group))
        print(
            f"- median force {lo:g}–{hi:g} N: {len(group)} people, hands recognised "
            f"{100 * pooled:.1f} % (people {100 * min(p[0] for p in group):.0f}–"
            f"{100 * max(p[0] for p in group):.0f} %)"
            if group
            else f"- {lo:g}–{hi:g} N: none"
        )
    print("\n| subject | split | hands | accuracy % | median force, N |\n|---|---|---|---|---|")
    shown = people if len(people) <= 13 else [*people[:8], None, *people[-5:]]
    for p in shown:
        print(
            "| … | | | | |"
            if p is None
            else f"| {p[2]} | {p[3]} | {p[4]} | {100 * p[0]:.0f} | {p[1]:.1f} |"
        )


if __name__ == "__main__":
    main()
