"""Scores by number of contacts (`learn.evaluate.contacts`) against slow references that loop
over the samples, on a tiny dataset whose samples hold one or two contacts; a dataset of one
contact per sample gets no such section."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from learn import metrics as M
from learn.evaluate.contacts import KEY, SplitContacts, contact_scores, contacts_section
from learn.evaluate.report import row_labels, write_report
from learn.evaluate.scoring import evaluate_checkpoint
from learn.inputs import net_input, net_labels, unpressed_as_background
from learn.train.checkpoint import load_checkpoint, model_from_checkpoint
from tactile import TactileMap
from tactile.dataset import DatasetWriter
from tactile.dataset.reader import DatasetReader
from tactile.geometry.synthetic import cylinder_sector_layout

from .conftest import GAIN, N_HAND, N_OTHER, make_sample

SECTION = "## By number of contacts"


def with_contacts(row: dict, i: int) -> dict:
    """``row`` (sample ``i``) as a mixing dataset writes it: every third sample two contacts
    (a second contactor of its own instance beside the first), the print all of contact 1."""
    n = 2 if i % 3 == 0 else 1
    pad = [-1] * (2 - n)
    return {
        **row,
        "n_contacts": np.uint8(n),
        "contact_subject": np.array([row["subject_id"]] + [-1] * (n - 1) + pad, np.int32),
        "contact_instance": np.array([row["instance_id"]] + [1000 + i] * (n - 1) + pad, np.int32),
        "instance_image": (row["image"] > 0).astype(np.uint8),
    }


@pytest.fixture(scope="module")
def mixed(tmp_path_factory):
    """The 48 samples of the tiny set, a third of them with two contacts."""
    folder = tmp_path_factory.mktemp("mixed") / "mix"
    layout, flat_mm = cylinder_sector_layout(width_mm=60, length_mm=90, pitch_mm=5)
    tmap = TactileMap.build(layout)
    writer = DatasetWriter(
        folder,
        config={"test": "tiny mix"},
        part="sector",
        generator_version="t",
        seed=3,
        tmap=tmap,
        layout=layout,
        attrs={"skin_counts_per_pa": GAIN},
    )
    rows = [with_contacts(make_sample(i, tmap, flat_mm), i) for i in range(N_HAND + N_OTHER)]
    writer.write_chunk(0, rows)
    writer.merge()
    return folder


def slow_accuracy(pred, y, n, hand) -> dict[str, tuple[int, int]]:
    """{group: (samples, right)} counted sample by sample; groups "k" (k contacts), "k hand"
    (a hand among them) and "k no hand"."""
    out: dict[str, list[int]] = {}
    for p, t, k, h in zip(pred.tolist(), y.tolist(), n.tolist(), hand.tolist(), strict=True):
        for group in (str(k), f"{k} hand" if h else f"{k} no hand"):
            tally = out.setdefault(group, [0, 0])
            tally[0] += 1
            tally[1] += int(p == t)
    return {k: tuple(v) for k, v in out.items()}


def test_scores_by_contacts_match_a_count_sample_by_sample():
    rng = np.random.default_rng(5)
    n, hand = rng.integers(1, 3, 40), rng.random(40) < 0.6
    y, pred = torch.from_numpy(rng.integers(0, 2, 40)), torch.from_numpy(rng.integers(0, 2, 40))
    got = contact_scores(pred, y, SplitContacts(n, hand), "classify", 2)[KEY]
    assert set(got) == {"1", "1 hand", "1 no hand", "2", "2 hand", "2 no hand"}
    for k, (samples, right) in slow_accuracy(pred, y, n, hand).items():
        s = got[k]
        assert s["n"] == samples and s["accuracy"] == pytest.approx(right / samples)
        assert s["low"] <= s["accuracy"] <= s["high"]
    # segmentation: hand samples only, one confusion matrix per number of contacts
    ys, ps = (torch.from_numpy(rng.integers(0, 7, (40, 3, 4))) for _ in range(2))
    seg = contact_scores(ps, ys, SplitContacts(n, hand), "segment", 7)[KEY]
    for k in (1, 2):
        cm = np.zeros((7, 7), np.int64)
        for i in range(40):
            if n[i] == k and hand[i]:
                for t, p in zip(ys[i].flatten().tolist(), ps[i].flatten().tolist(), strict=True):
                    cm[t, p] += 1
        assert seg[str(k)]["cm"] == cm.tolist() and seg[str(k)]["n"] == (hand & (n == k)).sum()


def test_evaluate_scores_each_test_sample_by_its_contacts(checkpoints, mixed, tmp_path, near_ties):
    """The rows of ``handskin evaluate`` against the dataset's test samples read one by one and
    counted by their own ``n_contacts``: the classifier on each image alone; the segmenter on
    the hand images at once (SegNet's unpooling of tied maxima differs with the batch size)."""
    rows = [evaluate_checkpoint(checkpoints[a], mixed, time_runs=2) for a in checkpoints]
    clf_net, seg_net = (
        model_from_checkpoint(load_checkpoint(checkpoints[a]))[0] for a in ("handsnet", "segnet")
    )
    clf_size, seg_size = rows[0]["input_size"], rows[1]["input_size"]
    tally: dict[str, list[int]] = {}
    scores: dict[str, list] = {}
    hand_x, hand_y, hand_k = [], [], []
    with DatasetReader(mixed) as r, torch.no_grad():
        for i in r.splits["test"]:
            k = int(r.n_contacts[i])
            image = r.image[i]
            x = torch.from_numpy(net_input(image, clf_size, "classify"))[None, None]
            logits = clf_net.eval()(x)
            right = int(logits.argmax(1)) == int(r.is_hand[i])
            for g in (str(k), f"{k} hand" if r.is_hand[i] else f"{k} no hand"):
                tally[g] = [a + b for a, b in zip(tally.get(g, [0, 0]), (1, right), strict=True)]
                scores.setdefault(g, []).append(logits[0].numpy())
            if r.is_hand[i]:
                hand_x.append(torch.from_numpy(net_input(image, seg_size, "segment"))[None])
                hand_y.append(torch.from_numpy(net_labels(r.label_image[i], seg_size)))
                hand_k.append(k)
        x = torch.stack(hand_x)
        seg_scores = seg_net.eval()(x)
        pred = unpressed_as_background(seg_scores.argmax(1), x)
        seg_scores = torch.where(x > 0, seg_scores, torch.eye(7)[0][:, None, None])  # background
    cms = {k: np.zeros((7, 7), np.int64) for k in (1, 2)}
    for p, y, k in zip(pred, hand_y, hand_k, strict=True):
        cms[k] += M.confusion_matrix(y, p, 7).numpy()
    by_k = {k: seg_scores[[j for j, kk in enumerate(hand_k) if kk == k]] for k in (1, 2)}
    clf, seg = rows[0][KEY], rows[1][KEY]
    assert set(clf) == set(tally) and clf["1"]["n"] + clf["2"]["n"] == rows[0]["n_test"]
    for k, (samples, right) in tally.items():
        assert clf[k]["n"] == samples
        near_ties.assert_rate(clf[k]["accuracy"], right / samples, np.stack(scores[k]))
    for k, cm in cms.items():
        near_ties.assert_cm(seg[str(k)]["cm"], cm, by_k[k])
        assert seg[str(k)]["n"] == hand_k.count(k)
    text = write_report(rows, tmp_path / "r.md").read_text()
    section = text.split(SECTION, 1)[1].split("\n## ", 1)[0]
    cm2 = np.asarray(seg["2"]["cm"])  # the row's, equal to cms[2] but at near ties
    miou = 100 * M.mean_iou(cm2)
    hand_miou = 100 * M.mean_iou(M.without_true_class(cm2))
    two = f"| 2, a hand among them | {hand_k.count(2)} | {miou:.2f} | {hand_miou:.2f} |"
    assert two in section
    s = clf["2"]
    assert f"| 2 contacts | {s['n']} | {100 * s['accuracy']:.2f} |" in section


def test_one_contact_per_sample_adds_no_section(checkpoints, tiny_dataset, tmp_path):
    rows = [evaluate_checkpoint(checkpoints[a], tiny_dataset, time_runs=2) for a in checkpoints]
    assert not any(KEY in r for r in rows)
    assert contacts_section(rows, row_labels(rows)) == []
    assert SECTION not in write_report(rows, tmp_path / "r.md").read_text()
