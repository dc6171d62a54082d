"""Accuracy by contact size and contactor against counts made by hand; segmentation scores by
group against a pixel-loop reference of Long et al.'s IoU."""

from __future__ import annotations

import numpy as np
import pytest

from learn.breakdown import (
    FORCE_EDGES_N,
    accuracy_by_active_taxels,
    accuracy_by_bins,
    accuracy_by_group,
    bin_labels,
    breakdown_markdown,
    group_markdown,
    hand_parts_group,
    hand_parts_groups,
    hands_by_group,
    parts_in_contact,
    press_forces_n,
    segmentation_by_group,
    segmentation_group_markdown,
)
from learn.worst import pack_labels, unpack_labels, worst_segmentations


def _reference_scores(pred: np.ndarray, truth: np.ndarray, k: int) -> tuple[float, float]:
    """Pixel accuracy and mIoU by counting pixels one by one (no confusion matrix): IoU of
    class c = |pred = c and truth = c| / |pred = c or truth = c| over classes in the truth."""
    p, t = pred.ravel().tolist(), truth.ravel().tolist()
    right = sum(a == b for a, b in zip(p, t, strict=True))
    ious = []
    for c in range(k):
        if c not in t:
            continue
        inter = sum(a == c and b == c for a, b in zip(p, t, strict=True))
        union = sum(a == c or b == c for a, b in zip(p, t, strict=True))
        ious.append(inter / union)
    return right / len(t), sum(ious) / len(ious)


def test_bins_and_per_class_accuracy_by_hand():
    n_active = np.array([3, 9, 10, 15, 25, 90, 200, 5])
    truth = np.array([1, 1, 0, 1, 0, 1, 0, 0])
    pred = np.array([0, 1, 0, 0, 1, 1, 0, 0])
    rows = accuracy_by_active_taxels(pred, truth, n_active, ["non_hand", "hand"], edges=(0, 10, 80))
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


def test_force_bins_by_hand_half_open_and_out_of_range():
    """Press forces (N) binned [lo, hi): an edge value goes up, NaN and negatives in no bin."""
    force = np.array([0.0, 4.99, 5.0, 12.0, 19.99, 20.0, 39.0, 40.0, 300.0, np.nan, -1.0])
    truth = np.array([1, 1, 0, 1, 1, 0, 1, 1, 0, 1, 0])
    pred = np.array([0, 1, 0, 0, 1, 0, 1, 1, 1, 1, 0])
    rows = accuracy_by_bins(pred, truth, force, ["non_hand", "hand"], FORCE_EDGES_N)
    assert [(r["lo"], r["hi"], r["n"]) for r in rows] == [
        (0, 5, 2),
        (5, 10, 1),
        (10, 20, 2),
        (20, 40, 2),
        (40, None, 2),
    ]
    assert rows[0]["per_class"]["hand"] == {"n": 2, "accuracy": 0.5}
    assert rows[2]["per_class"]["hand"] == {"n": 2, "accuracy": 0.5}
    assert rows[4]["per_class"]["non_hand"] == {"n": 1, "accuracy": 0.0}
    table = "\n".join(breakdown_markdown(rows, "press force", "N"))
    assert table.startswith("| press force | non_hand: samples")
    assert "| 0–5 N | 0 | – | 2 | 50.0 |" in table and "| 40+ N | 1 | 0.0 | 1 | 100.0 |" in table
    labels, order = bin_labels(force, FORCE_EDGES_N, "N")
    assert order == ["0–5 N", "5–10 N", "10–20 N", "20–40 N", "40+ N"]
    assert labels == [
        "0–5 N",
        "0–5 N",
        "5–10 N",
        "10–20 N",
        "10–20 N",
        "20–40 N",
        "20–40 N",
        "40+ N",
        "40+ N",
        "unknown",
        "unknown",
    ]


def test_lengths_must_agree():
    with pytest.raises(ValueError, match="length"):
        accuracy_by_active_taxels(np.zeros(3), np.zeros(2), np.zeros(3), ["a", "b"])


def test_accuracy_by_contactor_by_hand_least_accurate_first():
    groups = [
        "object: rake",
        "hand: right_hand",
        "object: rake",
        "body: elbow",
        "hand: right_hand",
        "object: rake",
    ]
    truth = np.array([0, 1, 0, 0, 1, 0])
    pred = np.array([1, 1, 0, 0, 0, 1])
    rows = accuracy_by_group(pred, truth, groups)
    assert [(r["group"], r["n"], r["errors"]) for r in rows] == [
        ("object: rake", 3, 2),
        ("hand: right_hand", 2, 1),
        ("body: elbow", 1, 0),
    ]
    assert rows[0]["accuracy"] == pytest.approx(1 / 3) and rows[1]["accuracy"] == 0.5
    assert "| object: rake | 3 | 2 | 33.3 |" in "\n".join(group_markdown(rows))
    with pytest.raises(ValueError, match="length"):
        accuracy_by_group(pred, truth, groups[:2])


def test_hand_parts_groups_by_hand():
    """Class ids 1..5 fingers, 6 palm, 0 none (tactile.CLASS_NAMES)."""
    cases = {
        (): "no part",
        (0,): "no part",
        (6,): "palm only",
        (0, 6): "palm only",
        (2,): "one finger",
        (1, 6): "palm + one finger",
        (2, 3): "two fingers",
        (1, 2, 6): "3 parts",
        (1, 2, 3, 4): "4 parts",
        (1, 2, 3, 4, 5, 6): "6 parts",
    }
    for parts, name in cases.items():
        assert hand_parts_group(set(parts)) == name, parts


def test_hands_by_group_skips_non_hands_and_keeps_the_given_order():
    groups = [None, "palm only", "3 parts", None, "palm only", "6 parts", "later"]
    truth = np.array([0, 1, 1, 0, 1, 1, 1])
    pred = np.array([1, 0, 1, 1, 1, 1, 0])  # the two non-hand errors must not count
    order = ("palm only", "3 parts", "6 parts")
    rows = hands_by_group(pred, truth, groups, order)
    assert [(r["group"], r["n"], r["errors"]) for r in rows] == [
        ("palm only", 2, 1),
        ("3 parts", 1, 0),
        ("6 parts", 1, 0),
        ("later", 1, 1),
    ]
    assert [r["group"] for r in hands_by_group(pred, truth, groups)][:2] == ["later", "palm only"]
    assert hands_by_group(pred, truth, [None] * 7) == []
    assert "| hand parts | samples |" in group_markdown(rows, "hand parts")[0]


@pytest.mark.parametrize("drop", [(), ("taxel_label", "label_image"), ("is_hand",)])
def test_hand_parts_groups_read_from_a_dataset(tmp_path, tiny_writer, drop):
    """Hands of the tiny set press a palm disc and four finger stripes (5 parts; no active
    threshold recorded, so every labelled taxel counts); non-hands get None. Without taxel
    labels a hand's parts are "unknown"; without ``is_hand`` no sample is known as a hand."""
    folder = tiny_writer(tmp_path / "d", [0, 1, 30, 31], drop)  # two hands, two blobs
    hand = "5 parts" if not drop else "unknown" if "taxel_label" in drop else None
    got = hand_parts_groups(folder, np.array([1, 2, 0, 3]))  # out of order on purpose
    assert got == [hand, None, hand, None]


def test_press_forces_read_in_any_order_and_none_without_the_field(tmp_path, tiny_writer):
    from tactile.dataset.reader import open_dataset

    folder = tiny_writer(tmp_path / "d", [0, 1, 30, 31])
    with open_dataset(folder) as reader:
        stored = reader["force_n"][:]
    np.testing.assert_array_equal(press_forces_n(folder, np.array([2, 0, 3])), stored[[2, 0, 3]])
    assert press_forces_n(tiny_writer(tmp_path / "e", [0, 30], ("force_n",)), np.arange(2)) is None


@pytest.mark.parametrize("seed", range(4))
def test_segmentation_by_group_against_pixel_counts(seed):
    """Random label images, some classes absent from a group: each group's scores equal the
    pixel-loop reference on that group's images alone."""
    rng = np.random.default_rng(seed)
    k, n = 7, 9
    truth = rng.integers(0, k, (n, 5, 6))
    truth[truth == 3] = 0  # class 3 never in the truth: skipped in every mean
    pred = np.where(rng.random(truth.shape) < 0.6, truth, rng.integers(0, k, truth.shape))
    groups = rng.choice(["hand: left_hand", "hand: right_hand", "action: grasp"], n)
    groups[:3] = ["hand: left_hand", "hand: right_hand", "action: grasp"]
    rows = segmentation_by_group(pred, truth, groups, k)
    assert [r["mean_iou"] for r in rows] == sorted(r["mean_iou"] for r in rows)
    for r in rows:
        m = groups == r["group"]
        acc, miou = _reference_scores(pred[m], truth[m], k)
        assert r["n"] == m.sum()
        assert r["pixel_accuracy"] == pytest.approx(acc) and r["mean_iou"] == pytest.approx(miou)
    named = segmentation_by_group(pred, truth, groups, k, by_name=True)
    assert [r["group"] for r in named] == sorted(set(groups))
    given = ["hand: right_hand", "action: grasp"]  # a group not named goes last
    ordered = segmentation_by_group(pred, truth, groups, k, order=given)
    assert [r["group"] for r in ordered] == [*given, "hand: left_hand"]
    text = "\n".join(segmentation_group_markdown(rows, "contactor"))
    r = rows[0]
    assert f"| {r['group']} | {r['n']} | {100 * r['pixel_accuracy']:.1f} |" in text
    with pytest.raises(ValueError, match="length"):
        segmentation_by_group(pred, truth, groups[:2], k)


def test_parts_in_contact_counts_hand_classes_only():
    truth = np.zeros((3, 4, 4), np.uint8)
    truth[1, 0, :3] = [1, 6, 6]  # thumb and palm
    truth[2] = np.arange(16).reshape(4, 4) % 7  # every class
    assert parts_in_contact(truth, 7).tolist() == [0, 2, 6]


@pytest.mark.parametrize("seed", [0, 1])
def test_worst_segmentations_per_image_against_pixel_counts(seed):
    """Each image's score is the pixel-loop reference on that image alone (classes absent from
    its truth skipped), records run from the lowest mIoU up, and the order indexes them."""
    rng = np.random.default_rng(seed)
    k, s = 7, 12
    truth = rng.integers(0, 3, (s, 6, 8))  # classes 3..6 absent from every truth
    truth[::3] = rng.integers(0, k, (len(truth[::3]), 6, 8))
    pred = np.where(rng.random(truth.shape) < 0.4, rng.integers(0, k, truth.shape), truth)
    pred[5] = truth[5]  # one perfect image
    indices = rng.permutation(100)[:s]
    actions = [f"a{i}" for i in range(s)]
    records, order = worst_segmentations(pred, truth, indices, k, {"action": actions})
    ref = [_reference_scores(pred[i], truth[i], k) for i in range(s)]
    assert sorted(order.tolist()) == list(range(s))
    for rec, i in zip(records, order, strict=True):
        assert rec["index"] == indices[i] and rec["action"] == actions[i]
        assert rec["pixel_accuracy"] == pytest.approx(ref[i][0], abs=1e-12)
        assert rec["mean_iou"] == pytest.approx(ref[i][1], abs=1e-12)
    mious = [r["mean_iou"] for r in records]
    assert mious == sorted(mious) and mious[-1] == 1.0 and records[-1]["index"] == indices[5]


def test_pack_labels_round_trip_and_range():
    labels = np.random.default_rng(0).integers(0, 7, (3, 68, 100)).astype(np.int64)
    packed = pack_labels(labels)
    assert set(packed) == {"shape", "zlib_base64"} and isinstance(packed["zlib_base64"], str)
    back = unpack_labels(packed)
    assert back.dtype == np.uint8 and np.array_equal(back, labels)
    with pytest.raises(ValueError, match=r"0\.\.255"):
        pack_labels(np.array([[[256]]]))


def test_svm_margin_against_a_loop():
    """Two classes: |score|; one-vs-rest: the top score less the runner-up, by a plain loop."""
    from learn.breakdown import svm_margin

    np.testing.assert_array_equal(svm_margin(np.array([-2.0, 0.5, 0.0])), [2.0, 0.5, 0.0])
    scores = np.random.default_rng(3).normal(size=(20, 4))
    ref = []
    for row in scores:
        best = max(range(4), key=lambda c: row[c])
        ref.append(row[best] - max(row[c] for c in range(4) if c != best))
    np.testing.assert_allclose(svm_margin(scores), ref)
