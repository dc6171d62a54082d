"""Evaluation: metrics of a known prediction against hand computations, checkpoint evaluation
and the markdown report beside the paper (VGG16 + SVM's row: test_vgg_svm.py; the fast
inference path: test_fastpath.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from torch import nn

from learn.data.load import TensorData
from learn.evaluate import paper
from learn.evaluate.report import confusion_markdown, write_report
from learn.evaluate.scoring import Job, evaluate_checkpoint, evaluate_job, read_test_split
from learn.train.validation import evaluate_tensors


class Oracle(nn.Module):
    """Logits that make class ``round(x.mean())`` win per image, or per pixel for images."""

    def __init__(self, per_pixel: bool, num_classes: int) -> None:
        super().__init__()
        self.per_pixel, self.num_classes = per_pixel, num_classes

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        cls = x[:, 0].round().long() if self.per_pixel else x.mean((1, 2, 3)).round().long()
        return nn.functional.one_hot(cls, self.num_classes).movedim(-1, 1).float()


def test_classification_metrics_by_hand():
    y = torch.tensor([0, 0, 1, 1, 1])
    pred = torch.tensor([0, 1, 1, 1, 0])
    data = TensorData(pred.float()[:, None, None, None].expand(5, 1, 2, 2).clone(), y)
    res = evaluate_tensors(Oracle(False, 2), data, 2, batch_size=2)
    assert res.cm.tolist() == [[1, 1], [1, 2]]
    assert res.metrics["accuracy"] == pytest.approx(3 / 5)
    assert res.metrics["mean_accuracy"] == pytest.approx((1 / 2 + 2 / 3) / 2)
    assert res.percent.flatten().tolist() == pytest.approx([50.0, 50.0, 100 / 3, 200 / 3])
    assert "| 0 | 50.00 | 50.00 |" in confusion_markdown(res.cm, ("0", "1"))
    assert res.predictions is None
    kept = evaluate_tensors(Oracle(False, 2), data, 2, batch_size=2, keep_predictions=True)
    assert kept.predictions.tolist() == pred.tolist() and kept.cm.tolist() == res.cm.tolist()


def test_segmentation_metrics_by_hand():
    y = torch.tensor([[[0, 0], [1, 2]]])  # (1, 2, 2)
    pred = torch.tensor([[[0, 1], [1, 1]]])
    res = evaluate_tensors(Oracle(True, 3), TensorData(pred.float()[:, None], y), 3)
    # cm = [[1,1,0],[0,1,0],[0,1,0]]; IoU: 1/2, 1/3, 0; t = 2, 1, 1
    assert res.metrics["pixel_accuracy"] == pytest.approx(2 / 4)
    assert res.metrics["mean_accuracy"] == pytest.approx((1 / 2 + 1 + 0) / 3)
    assert res.metrics["mean_iou"] == pytest.approx((1 / 2 + 1 / 3 + 0) / 3)
    assert res.metrics["fw_iou"] == pytest.approx((2 * 1 / 2 + 1 * 1 / 3 + 0) / 4)


def test_evaluate_checkpoint_and_report(checkpoints, tiny_dataset, tmp_path):
    rows = [evaluate_checkpoint(checkpoints[a], tiny_dataset, time_runs=3) for a in checkpoints]
    clf, seg = rows
    assert clf["task"] == "classify" and seg["task"] == "segment" and clf["n_test"] == 16
    assert sum(map(sum, clf["cm"])) == 16 and clf["ms_per_image"]["fast"] > 0
    assert abs(clf["fast_metrics"]["accuracy"] - clf["metrics"]["accuracy"]) <= 0.005
    text = write_report(rows, tmp_path / "report.md", "tiny").read_text()
    known = (
        paper.HANDSNET_ACCURACY_PCT,
        paper.HANDSNET_MS_PER_IMAGE,
        paper.SEGNET_ACC_PCT,
        paper.SEGNET_MIOU_PCT,
        paper.SEGNET_MS_PER_IMAGE,
    )
    for needle in (
        "paper",
        *(f"{v:.2f}" for v in known),
        "unknown",
        "| BoVW | not run",
        f"{100 * clf['metrics']['accuracy']:.2f}",
        "| true \\ predicted |",
        "IoU per class (%)",
        "The same predictions on the hand's pixels",
    ):
        assert needle in text, needle
    assert json.loads((tmp_path / "report.json").read_text()) == json.loads(json.dumps(rows))
    # the hand-pixel table: the share of hand pixels, and the scores of the hand pixels alone
    seg_cm = np.asarray(seg["cm"])
    share = 100 * seg_cm[1:].sum() / seg_cm.sum()
    assert f"The hand's pixels are {share:.2f} % of" in text
    hand_acc = 100 * np.trace(seg_cm[1:, 1:]) / seg_cm[1:].sum()
    section = text.split("on the hand's pixels", 1)[1].split("\n## ", 1)[0]
    (hand_row,) = [ln for ln in section.splitlines() if ln.startswith("| SegNet |")]
    assert hand_row.startswith(f"| SegNet | {hand_acc:.2f} |"), hand_row


def test_report_tells_models_of_one_method_apart(checkpoints, tiny_dataset, tmp_path):
    """Two HandsNets of one run folder trained on different data: two rows named by their
    training data, each beside the paper's number; two of other folders: named by folder."""
    row = evaluate_checkpoint(checkpoints["handsnet"], tiny_dataset, time_runs=3)
    assert row["train_data"]["path"] == row["test_data"] == str(tiny_dataset)
    other = dict(
        row,
        train_data={"path": "/data/forearm3x", "n_train": 6300},
        metrics=dict(row["metrics"], accuracy=0.5),
    )
    text = write_report([row, other], tmp_path / "r.md").read_text()
    mine = f"| HandsNet, handsnet, {tiny_dataset.name} | {100 * row['metrics']['accuracy']:.2f} |"
    assert mine in text
    assert (
        "| HandsNet, handsnet, forearm3x | 50.00 |" in text and "forearm3x (6,300 images)" in text
    )
    paper_acc = f"{paper.HANDSNET_ACCURACY_PCT:.2f}"
    assert sum(line.count(paper_acc) for line in text.splitlines() if "| HandsNet," in line) == 2
    assert "| HandsNet | not run" not in text  # no empty row for the method itself
    same = write_report([row, dict(row, checkpoint="/runs/b/best.pt")], tmp_path / "s.md")
    assert "| HandsNet, b |" in same.read_text()  # same data: the run folder tells them apart


def _model_and_test_split(ckpt_path, data):
    """The checkpoint's model, its un-flipped test split and that split in memory."""
    from learn.data.load import materialize, open_split
    from learn.train.checkpoint import load_checkpoint, model_from_checkpoint

    model, run = model_from_checkpoint(load_checkpoint(ckpt_path))
    split = open_split(data, "test", run.task, run.model.input_size, None, run.train.seed)
    return model, split, materialize(split, "test", False)


def test_rows_of_one_evaluate_read_the_test_split_once(
    checkpoints, tiny_dataset, tmp_path, monkeypatch
):
    """Rows that share data and input read the test split once; the tensors equal a fresh read
    (`open_split` + `materialize`); other data, another input size or a rewritten dataset
    read afresh."""
    import os
    import shutil
    from dataclasses import replace

    import learn.evaluate.scoring as scoring
    from learn.train.checkpoint import load_checkpoint, model_from_checkpoint

    reads = []
    real = scoring.materialize
    monkeypatch.setattr(
        scoring, "materialize", lambda ds, *a, **k: reads.append(len(ds)) or real(ds, *a, **k)
    )
    copy = shutil.copytree(tiny_dataset, tmp_path / "copy")
    _, run = model_from_checkpoint(load_checkpoint(checkpoints["handsnet"]))
    _, _, fresh = _model_and_test_split(checkpoints["handsnet"], tiny_dataset)
    n = len(reads)  # the fresh read above
    got = read_test_split(copy, run, None)
    assert len(reads) == n + 1
    assert torch.equal(got.x, fresh.x) and torch.equal(got.y, fresh.y)
    evaluate_checkpoint(checkpoints["handsnet"], copy, time_runs=2)
    evaluate_job(Job((checkpoints["handsnet"],), tta=True), copy, time_runs=2)
    assert len(reads) == n + 1  # two rows, no new read
    bigger = replace(run, model=replace(run.model, input_size=(40, 60)))
    other = read_test_split(copy, bigger, None)
    assert len(reads) == n + 2 and other.x.shape[-2:] == (40, 60)
    read_test_split(copy, run, None)
    assert len(reads) == n + 3  # the cache holds the last split only
    h5 = copy / "dataset.h5"
    os.utime(h5, ns=(h5.stat().st_atime_ns, h5.stat().st_mtime_ns + 10**9))
    read_test_split(copy, run, None)
    assert len(reads) == n + 4  # rewritten data is read again
    read_test_split(tiny_dataset, run, None)
    assert len(reads) == n + 5
