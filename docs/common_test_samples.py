"""Two parts' models compared on the presses both held out: paired scores across datasets.

    python docs/common_test_samples.py reports/density/x1.json reports/density/x4.json

Datasets generated with one seed on different parts (``handskin generate --part forearm`` and
``--part forearm_x4``) hold mostly the same presses: sample i is the same person, contactor,
pose and force plan unless a rejected episode was redrawn; only the aim is each skin's own (one
draw over that part's taxels, `sim.placement.draw_aim_taxel`), so the print lies elsewhere on
the map. Their default (greedy) test splits still differ (the split balances the subjects'
sample counts, which a redraw changes), so two `handskin evaluate` reports score their models on
partly different people; datasets generated with ``--split keyed`` hold out the same people and
keep nearly all their test presses in common. This script keeps the samples that are in both
test splits with the same episode seed and subject — the same person, contactor and press plan
on each skin — and compares every row of report A with the row of report B of the same method:
classifiers by accuracy and McNemar's exact test on the samples exactly one gets right,
segmenters by mIoU; both with a paired 95 % interval of B − A that redraws whole test subjects
and object instances (`learn.cluster_bootstrap`, as the reports' "subjects resampled" columns):
prints of one person are alike, so single samples are not independent.
A report row names the dataset it was scored on (``test_data``); the same press is read from
that dataset, so a model scored on another part's dataset (``handskin evaluate --data``) is
compared on the presses of the data it was scored on. Rows written before that field was added
are taken to be scored on their training dataset. The datasets must be at the recorded paths.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from learn.cluster_bootstrap import (
    grouped_difference_interval,
    grouped_mean_iou_difference_interval,
)
from learn.row_labels import method_label
from learn.significance import batched_mean_iou, mcnemar_p
from tactile.dataset import open_dataset


def press_keys(data_dir: Path) -> np.ndarray:
    """(S, 2) int64 (episode seed, subject id) of every sample: which press it is."""
    with open_dataset(data_dir) as ds:
        s = ds.file["samples"]
        return np.column_stack(
            [
                np.asarray(s["episode_seed"][:]).astype(np.int64),
                np.asarray(s["subject_id"][:]).astype(np.int64),
            ]
        )


def scored_on(row: dict) -> Path:
    """The dataset a report row was scored on (older rows: their training dataset)."""
    return Path(row.get("test_data") or row["train_data"]["path"])


def common(a: dict, b: dict) -> np.ndarray:
    """Sample indices in both rows' test splits whose press is the same in the datasets the rows
    were scored on."""
    ka, kb = (press_keys(scored_on(r)) for r in (a, b))
    both = np.intersect1d(a["test_indices"], b["test_indices"])
    both = both[(both < len(ka)) & (both < len(kb))]
    return both[np.all(ka[both] == kb[both], axis=1)]


def position(row: dict, idx: np.ndarray) -> np.ndarray:
    """Where each of ``idx`` sits in the row's ``test_indices``."""
    order = {int(i): k for k, i in enumerate(row["test_indices"])}
    return np.array([order[int(i)] for i in idx])


def groups_of(row: dict, idx: np.ndarray) -> np.ndarray:
    """Subject / object-instance group code (`learn.cluster_bootstrap.sample_groups`) of each of
    ``idx`` in ``row``: the same press, so the same person or object in both reports."""
    return np.asarray(row["test_groups"], dtype=np.int64)[position(row, idx)]


def _points(interval: tuple[float, float]) -> str:
    return f"{100 * interval[0]:+.2f} to {100 * interval[1]:+.2f}"


def compare_classifiers(a: dict, b: dict, idx: np.ndarray) -> str:
    right = [~np.isin(idx, [e["index"] for e in r["errors"]]) for r in (a, b)]
    only_a, only_b = int((right[0] & ~right[1]).sum()), int((right[1] & ~right[0]).sum())
    acc = [100 * r.mean() for r in right]
    diff = grouped_difference_interval(right[1], right[0], groups_of(a, idx))
    return (
        f"{len(idx)} common test samples: accuracy A {acc[0]:.2f} %, B {acc[1]:.2f} % "
        f"(B − A {acc[1] - acc[0]:+.2f} points, 95 % interval with subjects redrawn "
        f"{_points(diff)}); only A right {only_a}, only B right {only_b}, McNemar p = "
        f"{mcnemar_p(only_a, only_b):.3g}"
    )


def compare_segmenters(a: dict, b: dict, idx: np.ndarray) -> str:
    cms = [np.asarray(r["per_image_cm"], dtype=np.float64)[position(r, idx)] for r in (a, b)]
    miou = [100 * float(batched_mean_iou(cm.sum(0)[None])[0]) for cm in cms]
    diff = grouped_mean_iou_difference_interval(cms[1], cms[0], groups_of(a, idx))
    return (
        f"{len(idx)} common test images: mIoU A {miou[0]:.2f} %, B {miou[1]:.2f} % "
        f"(B − A {miou[1] - miou[0]:+.2f} points, 95 % interval with subjects redrawn "
        f"{_points(diff)})"
    )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("a", type=Path, help="report JSON of handskin evaluate (A)")
    ap.add_argument("b", type=Path, help="report JSON of handskin evaluate (B)")
    args = ap.parse_args()
    rows_a, rows_b = (json.loads(p.read_text()) for p in (args.a, args.b))
    for a in rows_a:
        if a.get("members") or a.get("tta_views") or a.get("test_indices") is None:
            continue
        match = [
            b
            for b in rows_b
            if b["task"] == a["task"]
            and not b.get("members")
            and not b.get("tta_views")
            and method_label(b) == method_label(a)
        ]
        for b in match:
            idx = common(a, b)
            if a["task"] == "classify":
                text = compare_classifiers(a, b, idx)
            elif a.get("per_image_cm") is not None and b.get("per_image_cm") is not None:
                text = compare_segmenters(a, b, idx)
            else:
                continue
            print(f"{method_label(a)}: A = {a['checkpoint']}, B = {b['checkpoint']}\n  {text}")


if __name__ == "__main__":
    main()
