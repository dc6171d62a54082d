"""Accuracy by contact size against counts made by hand."""

from __future__ import annotations

import numpy as np
import pytest

from learn.breakdown import (
    accuracy_by_active_taxels,
    accuracy_by_group,
    breakdown_markdown,
    group_markdown,
)


def test_bins_and_per_class_accuracy_by_hand():
    n_active = np.array([3, 9, 10, 15, 25, 90, 200, 5])
    truth = np.array([1, 1, 0, 1, 0, 1, 0, 0])
    pred = np.array([0, 1, 0, 0, 1, 1, 0, 0])
    rows = accuracy_by_active_taxels(pred, truth, n_active, ["non_hand", "hand"],
                                     edges=(0, 10, 80))  # fmt: skip
    assert [(r["lo"], r["hi"], r["n"]) for r in rows] == [(0, 10, 3), (10, 80, 3), (80, None, 2)]
    first, middle, last = (r["per_class"] for r in rows)
    assert first["hand"] == {"n": 2, "accuracy": 0.5}
    assert first["non_hand"] == {"n": 1, "accuracy": 1.0}
    assert middle["hand"] == {"n": 1, "accuracy": 0.0}
    assert middle["non_hand"] == {"n": 2, "accuracy": 0.5}
    assert last["hand"]["accuracy"] == 1.0 and last["non_hand"]["accuracy"] == 1.0
    empty = accuracy_by_active_taxels(pred[:1], truth[:1], n_active[:1], ["non_hand", "hand"])
    assert empty[0]["per_class"]["non_hand"] == {"n": 0, "accuracy": None}
    table = "\n".join(breakdown_markdown(rows))
    assert "| 0–9 | 1 | 100.0 | 2 | 50.0 |" in table and "| 80+ | 1 | 100.0 | 1 | 100.0 |" in table


def test_lengths_must_agree():
    with pytest.raises(ValueError, match="length"):
        accuracy_by_active_taxels(np.zeros(3), np.zeros(2), np.zeros(3), ["a", "b"])


def test_accuracy_by_contactor_by_hand_least_accurate_first():
    groups = ["object: rake", "hand: right_hand", "object: rake", "body: elbow", "hand: right_hand",
              "object: rake"]  # fmt: skip
    truth = np.array([0, 1, 0, 0, 1, 0])
    pred = np.array([1, 1, 0, 0, 0, 1])
    rows = accuracy_by_group(pred, truth, groups)
    assert [(r["group"], r["n"], r["errors"]) for r in rows] == [
        ("object: rake", 3, 2), ("hand: right_hand", 2, 1), ("body: elbow", 1, 0)]
    assert rows[0]["accuracy"] == pytest.approx(1 / 3) and rows[1]["accuracy"] == 0.5
    assert "| object: rake | 3 | 2 | 33.3 |" in "\n".join(group_markdown(rows))
    with pytest.raises(ValueError, match="length"):
        accuracy_by_group(pred, truth, groups[:2])
