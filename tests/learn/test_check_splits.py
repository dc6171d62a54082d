"""docs/check_splits.py scores a classifier on the splits its training used: its test split
agrees with `handskin evaluate`'s confusion matrix, and its training and validation parts
re-make the train split, with no person in both."""

from __future__ import annotations

import sys

import numpy as np

from learn.evaluate import evaluate_checkpoint
from tactile.dataset.reader import open_dataset


def test_check_splits_scores_the_splits_training_used(
    doc_script, checkpoints, tiny_dataset, capsys, monkeypatch
):
    script = doc_script("check_splits")
    parts = script.split_predictions(checkpoints["handsnet"], tiny_dataset)
    row = evaluate_checkpoint(checkpoints["handsnet"], tiny_dataset, time_runs=2, time_rounds=1)
    idx, right = parts["test"]
    cm = np.asarray(row["cm"])
    assert len(idx) == cm.sum() and right.sum() == np.trace(cm)
    with open_dataset(tiny_dataset) as reader:
        train, subject = reader.splits["train"], reader["subject_id"][:]
    fit_idx, val_idx = parts["train"][0], parts["val"][0]
    assert len(val_idx) > 0
    np.testing.assert_array_equal(np.sort(np.concatenate([fit_idx, val_idx])), np.sort(train))
    assert not (set(subject[val_idx].tolist()) & set(subject[fit_idx].tolist())) - {-1}
    monkeypatch.setattr(
        sys, "argv", ["check_splits.py", str(checkpoints["handsnet"]), str(tiny_dataset)]
    )
    script.main()
    out = capsys.readouterr().out
    test_row = f"| test | {len(idx)} | {100 * right.mean():.2f} |"
    assert test_row in out and "| split | 0–5 N | 5–10 N |" in out
