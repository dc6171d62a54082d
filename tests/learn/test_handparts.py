"""A class-and-parts network (`learn.models.compact.HandParts`, task "both") through training,
scoring, prediction and the frame path, on the tiny dataset: its targets against the segment
task's, its loss against a closed form, its scores against per-image references, and the frame
path's answers against `predict_frame` with one network pass per frame."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch
from torch import nn

from learn.config import preset_run
from learn.data.dataset import TorchTactileDataset
from learn.data.load import load_data
from learn.evaluate.scoring import evaluate_checkpoint, report_rows
from learn.infer.predict import load_map, load_predictor, predict_frame
from learn.infer.stream import Recognizer
from learn.train.loop import fit
from learn.train.losses import BothLoss, class_weights
from learn.train.validation import evaluate_tensors
from tactile.dataset import open_dataset
from tactile.images.labels import IGNORE

SIZE = (32, 48)


@pytest.fixture(scope="module")
def both_run(tiny_dataset, tmp_path_factory):
    """A HandParts trained for 3 epochs on the tiny set, its run and data."""
    run = preset_run("handparts", epochs=3, batch_size=8)
    run = dataclasses.replace(run, model=dataclasses.replace(run.model, input_size=SIZE), threads=1)
    data = load_data(tiny_dataset, run, progress=False)
    out = tmp_path_factory.mktemp("handparts")
    fit(run, data, out, progress=False)
    return out / "best.pt", run, data


def test_targets_are_the_segment_tasks_with_non_hands_ignored(tiny_dataset):
    both = TorchTactileDataset(tiny_dataset, "test", "both", SIZE, flips=False)
    seg = TorchTactileDataset(tiny_dataset, "test", "segment", SIZE, flips=False, hand_only=False)
    hand = open_dataset(tiny_dataset).is_hand[:]
    assert len(both) == len(seg) and 0 < hand[both.indices].sum() < len(both)
    for j, i in enumerate(both.indices):
        (xb, yb), (xs, ys) = both[j], seg[j]
        assert torch.equal(xb, xs)
        assert torch.equal(yb, ys) if hand[i] else bool((yb == IGNORE).all())


def test_both_loss_is_class_ce_plus_the_parts_loss_on_hands():
    torch.manual_seed(0)
    y = torch.randint(0, 7, (4, 6, 5))
    y[1], y[3] = IGNORE, IGNORE  # two non-hands
    logits = (torch.randn(4, 2), torch.randn(4, 7, 6, 5))
    w = class_weights(y, 7)
    got = BothLoss("weighted_ce", w)(logits, y)
    hands = torch.tensor([0, 2])
    want = nn.functional.cross_entropy(logits[0], torch.tensor([1, 0, 1, 0]))
    want += nn.functional.cross_entropy(
        logits[1][hands], y[hands], weight=torch.tensor(w, dtype=torch.float32)
    )
    assert got.item() == pytest.approx(want.item(), rel=1e-6)


def test_scores_are_the_per_image_references(both_run):
    path, run, data = both_run
    model = load_predictor(path).model
    res = evaluate_tensors(model, data.test, 7)
    with torch.no_grad():
        outs = [model(x[None]) for x in data.test.x]
    is_hand = (data.test.y != IGNORE).flatten(1).any(1)
    said = torch.stack([o[0][0].argmax() for o in outs])
    cm = np.zeros((2, 2), int)
    for t, p in zip(is_hand.long().tolist(), said.tolist(), strict=True):
        cm[t, p] += 1
    assert res.class_cm.tolist() == cm.tolist()
    assert res.metrics["class_accuracy"] == pytest.approx(np.trace(cm) / cm.sum())
    pixels = int((data.test.y[is_hand] >= 0).sum())
    assert int(res.cm.sum()) == pixels  # the parts are scored on the hands' pixels only
    rows = report_rows(evaluate_checkpoint(path, data_path(run, data), time_runs=2))
    assert [r["task"] for r in rows] == ["classify", "segment"] and all(r["one_pass"] for r in rows)
    assert rows[0]["cm"] == cm.tolist() and rows[0]["n_test"] == len(data.test.y)


def data_path(run, data) -> str:
    return data.description["path"]


def test_the_frame_path_answers_as_predict_frame_in_one_pass(both_run, tiny_dataset):
    path, _, _ = both_run
    torch.set_num_threads(1)
    pred = load_predictor(path)
    tmap, _, to_pa = load_map(tiny_dataset)
    raw = open_dataset(tiny_dataset).raw[:]
    calls = []
    counted = dataclasses.replace(pred, model=Counted(pred.model, calls))
    rec = Recognizer(tmap, counted)
    for r in [*raw, np.zeros_like(raw[0])]:
        p = to_pa(r)
        before = len(calls)
        answer, ref = rec.step(p), predict_frame(p, tmap, pred)
        assert len(calls) - before <= 1  # class and parts from one pass (none for no touch)
        assert answer.class_name == ref.class_name
        assert answer.probability == pytest.approx(ref.probability, abs=2e-6)
        assert np.array_equal(answer.taxel_labels, ref.taxel_labels)
    with pytest.raises(Exception, match="answers both; give it alone"):
        Recognizer(tmap, pred, load_predictor(path))


class Counted(nn.Module):
    """A network that records each call."""

    def __init__(self, net: nn.Module, calls: list) -> None:
        super().__init__()
        self.net, self.calls = net, calls

    def forward(self, x):
        self.calls.append(1)
        return self.net(x)


def test_stream_command_answers_as_predict_frame(both_run, tiny_dataset):
    """`handskin stream --classifier HANDPARTS.pt` over standard input: one JSON line a frame,
    each `predict_frame`'s class, probability and taxel labels."""
    import json
    import subprocess
    import sys

    path, _, _ = both_run
    tmap, _, to_pa = load_map(tiny_dataset)
    raw = open_dataset(tiny_dataset).raw[:12].astype(np.int64)
    lines = b"".join(",".join(map(str, r)).encode() + b"\n" for r in raw)
    cmd = [sys.executable, "-c", "from handskin.cli import main; main()", "stream"]
    cmd += ["--map", str(tiny_dataset), "--classifier", str(path), "--threads", "1"]
    res = subprocess.run(cmd, input=lines, capture_output=True, check=True)
    answers = [json.loads(line) for line in res.stdout.splitlines()]
    pred = load_predictor(path)
    assert len(answers) == len(raw)
    for a, r in zip(answers, raw, strict=True):
        ref = predict_frame(to_pa(r), tmap, pred)
        assert a["class"] == ref.class_name
        assert a["probability"] == pytest.approx(ref.probability, abs=2e-6)
        assert a["taxel_labels"] == ref.taxel_labels.tolist()
