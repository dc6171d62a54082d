"""Evaluation: metrics of a known prediction against hand computations, checkpoint evaluation
and the markdown report beside the paper (VGG16 + SVM's row: test_vgg_svm.py; the fast
inference path: test_fastpath.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import torch
from torch import nn

from learn.eval_report import confusion_markdown, write_report
from learn.evaluate import (
    evaluate_checkpoint,
    evaluate_tensors,
    read_test_split,
)
from learn.experiments import paper
from learn.folder import TensorData
from tactile.dataset.reader import DatasetReader


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
        "not run",
        f"{100 * clf['metrics']['accuracy']:.2f}",
        "% of each true class",
        "Accuracy by contact size",
        "mIoU (%) of coarser groupings",
        "mirror pairs merged",
        "The same predictions on the hand's pixels",
    ):
        assert needle in text, needle
    # the hand-pixel table: the share of hand pixels, and the scores of the hand pixels alone
    seg_cm = np.asarray(seg["cm"])
    share = 100 * seg_cm[1:].sum() / seg_cm.sum()
    assert f"The hand's pixels are {share:.2f} % of the test images' pixels" in text
    hand_acc = 100 * np.trace(seg_cm[1:, 1:]) / seg_cm[1:].sum()
    section = text.split("on the hand's pixels", 1)[1].split("\n## ", 1)[0]
    (hand_row,) = [ln for ln in section.splitlines() if ln.startswith("| SegNet |")]
    assert hand_row.startswith(f"| SegNet | {hand_acc:.2f} |"), hand_row
    # the size breakdown re-adds to the confusion matrix's diagonal, class by class
    per_bin = clf["by_active_taxels"]
    for c, name in enumerate(clf["class_names"]):
        n = sum(b["per_class"][name]["n"] for b in per_bin)
        right = sum(
            b["per_class"][name]["n"] * (b["per_class"][name]["accuracy"] or 0) for b in per_bin
        )
        assert n == sum(clf["cm"][c]) and round(right) == clf["cm"][c][c]
    # so does the one by press force, from the dataset's force_n
    with DatasetReader(tiny_dataset) as reader:
        force = reader["force_n"][reader.splits["test"]]
    for c, name in enumerate(clf["class_names"]):
        assert sum(b["per_class"][name]["n"] for b in clf["by_force"]) == sum(clf["cm"][c])
    assert [b["n"] for b in clf["by_force"]] == [
        int(np.sum((force >= b["lo"]) & (force < (b["hi"] or np.inf)))) for b in clf["by_force"]
    ]
    assert "Accuracy by press force" in text and "| 40+ N |" in text
    forces = seg["segmentation_by_group"]["press force"]
    assert [g["group"] for g in forces] == [
        g
        for g in ("0–5 N", "5–10 N", "10–20 N", "20–40 N", "40+ N")
        if g in {f["group"] for f in forces}
    ]
    assert sum(g["n"] for g in forces) == seg["n_test"]
    # so does the contactor breakdown (this dataset stores no contactor field: one "unknown")
    groups = clf["by_contactor"]
    assert [g["group"] for g in groups] == ["unknown"] and groups[0]["n"] == 16
    cm = np.asarray(clf["cm"])
    assert groups[0]["errors"] == cm.sum() - np.trace(cm)
    assert seg["by_active_taxels"] is None and seg["by_contactor"] is None
    # the hand samples by parts pressing and by action re-add to the confusion matrix's hand row
    hand = clf["class_names"].index("hand")
    for key in ("hands_by_parts", "hands_by_action"):
        assert sum(g["n"] for g in clf[key]) == sum(clf["cm"][hand]), key
        assert sum(g["errors"] for g in clf[key]) == sum(clf["cm"][hand]) - cm[hand, hand], key
    assert [g["group"] for g in clf["hands_by_action"]] == ["unknown"]  # no action stored
    # every tiny hand is a palm disc and four finger stripes, and no threshold is recorded
    assert [g["group"] for g in clf["hands_by_parts"]] == ["5 parts"]
    assert "Accuracy on the hand samples by the hand parts" in text
    assert seg["hands_by_parts"] is None
    # the segmenter's groups: every test image in one group per grouping, and the hand-parts
    # groups re-add to the whole test split's pixel count
    by = seg["segmentation_by_group"]
    assert set(by) == {"contactor", "action", "hand parts touching", "press force"}
    assert all(sum(r["n"] for r in rows) == seg["n_test"] for rows in by.values())
    assert [r["group"] for r in by["action"]] == ["unknown"]  # the tiny set stores no action
    assert by["action"][0]["mean_iou"] == pytest.approx(seg["metrics"]["mean_iou"])
    assert "| hand parts touching | images | pixel accuracy % | mIoU % |" in text


def test_report_tells_models_of_one_method_apart(checkpoints, tiny_dataset, tmp_path):
    """Two HandsNets trained on different data: two labelled rows, each beside the paper's
    number and naming its training data; one "trained on" line per model in the details."""
    row = evaluate_checkpoint(checkpoints["handsnet"], tiny_dataset, time_runs=3)
    assert row["train_data"]["path"] == row["test_data"] == str(tiny_dataset)
    other = dict(
        row,
        train_data={"path": "/data/forearm3x", "n_train": 6300},
        metrics=dict(row["metrics"], accuracy=0.5),
    )
    text = write_report([row, other], tmp_path / "r.md").read_text()
    name = tiny_dataset.name
    n = row["train_data"]["n_train"]
    mine = f"| HandsNet, {name} ({n:,} train) | {100 * row['metrics']['accuracy']:.2f} |"
    assert mine in text
    theirs = "| HandsNet, forearm3x (6,300 train) | 50.00 |"
    assert theirs in text
    paper_acc = f"{paper.HANDSNET_ACCURACY_PCT:.2f}"
    assert sum(line.count(paper_acc) for line in text.splitlines() if "| HandsNet," in line) == 2
    assert "| HandsNet | not run" not in text  # no empty row for the method itself
    assert "Trained on: forearm3x (6,300 train). Initialisation: random (seeded)." in text
    same = write_report([row, dict(row, checkpoint="/runs/b/best.pt")], tmp_path / "s.md")
    assert ", b |" in same.read_text()  # same data too: the run folder tells them apart


def test_report_of_one_task_states_the_other_tasks_paper_values(
    checkpoints, tiny_dataset, tmp_path
):
    """A classifier-only report gives Table 8 as one sentence with the paper's SegNet values,
    not a table of rows that were not run; a segmenter-only one does the same for Table 3."""
    for arch, empty, values, absent, listed in (
        (
            "handsnet",
            "No segmenter was scored",
            (paper.SEGNET_ACC_PCT, paper.SEGNET_MIOU_PCT, paper.SEGNET_MS_PER_IMAGE),
            ("| SegNet |", "| FCN |"),
            "| BoVW | not run |",
        ),
        (
            "segnet",
            "No classifier was scored",
            (paper.HANDSNET_ACCURACY_PCT, paper.HANDSNET_MS_PER_IMAGE),
            ("| HandsNet |", "| VGG16 fine-tuned |", "| BoVW |"),
            "| FCN | not run |",
        ),
    ):
        row = evaluate_checkpoint(checkpoints[arch], tiny_dataset, time_runs=2)
        text = write_report([row], tmp_path / f"{arch}.md").read_text()
        (line,) = [ln for ln in text.splitlines() if ln.startswith(empty)]
        assert all(f"{v:.2f}" in line for v in values), line
        assert not any(a in text for a in absent)  # no rows for the task nothing was run of
        assert listed in text  # the scored task still lists the paper's other methods


def _model_and_test_split(ckpt_path, data):
    """The checkpoint's model, its un-flipped test split and that split in memory."""
    from learn.checkpoint import load_checkpoint, model_from_checkpoint
    from learn.folder import materialize, open_split

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

    import learn.folder
    from learn.checkpoint import load_checkpoint, model_from_checkpoint

    reads = []
    real = learn.folder.materialize
    monkeypatch.setattr(
        learn.folder, "materialize", lambda ds, *a, **k: reads.append(len(ds)) or real(ds, *a, **k)
    )
    copy = shutil.copytree(tiny_dataset, tmp_path / "copy")
    _, run = model_from_checkpoint(load_checkpoint(checkpoints["handsnet"]))
    _, fresh_split, fresh = _model_and_test_split(checkpoints["handsnet"], tiny_dataset)
    n = len(reads)  # the fresh read above
    split, got = read_test_split(copy, run, None)
    assert len(reads) == n + 1
    assert np.array_equal(split.indices, fresh_split.indices)
    assert torch.equal(got.x, fresh.x) and torch.equal(got.y, fresh.y)
    evaluate_checkpoint(checkpoints["handsnet"], copy, time_runs=2)
    evaluate_checkpoint(checkpoints["handsnet"], copy, time_runs=2, tta=True)
    assert len(reads) == n + 1  # two rows, no new read
    bigger = replace(run, model=replace(run.model, input_size=(40, 60)))
    _, other = read_test_split(copy, bigger, None)
    assert len(reads) == n + 2 and other.x.shape[-2:] == (40, 60)
    read_test_split(copy, run, None)
    assert len(reads) == n + 3  # the cache holds the last split only
    h5 = copy / "dataset.h5"
    os.utime(h5, ns=(h5.stat().st_atime_ns, h5.stat().st_mtime_ns + 10**9))
    read_test_split(copy, run, None)
    assert len(reads) == n + 4  # rewritten data is read again
    read_test_split(tiny_dataset, run, None)
    assert len(reads) == n + 5


def test_errors_most_confident_first_and_their_sheet(checkpoints, tiny_dataset, tmp_path):
    """A classifier row lists exactly the samples a plain softmax of the model gets wrong, most
    confident first; `handskin evaluate` draws the sheet of them and links it in the report."""
    import typer
    from typer.testing import CliRunner

    from learn.checkpoint import load_checkpoint, save_checkpoint
    from learn.cli import register

    ckpt = load_checkpoint(checkpoints["handsnet"])  # noisy weights: a classifier that errs
    gen = torch.Generator().manual_seed(5)
    ckpt["model"] = {
        k: v + 0.3 * torch.randn(v.shape, generator=gen) * v.std()
        if v.is_floating_point() and v.numel() > 1
        else v
        for k, v in ckpt["model"].items()
    }
    noisy = save_checkpoint(ckpt, tmp_path / "noisy" / "best.pt")
    row = evaluate_checkpoint(noisy, tiny_dataset, time_runs=2)
    model, split, test = _model_and_test_split(noisy, tiny_dataset)
    with torch.no_grad():
        p = model(test.x).double().softmax(1).numpy()
    wrong = np.flatnonzero(p.argmax(1) != test.y.numpy())
    assert len(wrong) > 0, "the noisy classifier should err on the tiny test split"
    expected = sorted(wrong, key=lambda k: -p[k].max())
    assert [e["index"] for e in row["errors"]] == [int(split.indices[k]) for k in expected]
    np.testing.assert_allclose(
        [e["probability"] for e in row["errors"]], [p[k].max() for k in expected], rtol=1e-5
    )
    names = row["class_names"]
    assert all(
        e["true"] == names[int(test.y[k])] for e, k in zip(row["errors"], expected, strict=True)
    )
    app = typer.Typer()
    register(app)
    md = tmp_path / "rep" / "r.md"
    md.parent.mkdir()
    res = CliRunner().invoke(
        app, ["evaluate", str(noisy), "--data", str(tiny_dataset), "--report", str(md)]
    )
    assert res.exit_code == 0, res.output
    sheet = md.parent / "r_errors_HandsNet.png"
    assert sheet.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"![most confident errors]({sheet.name})" in md.read_text()
    assert json.loads(md.with_suffix(".json").read_text())[0]["error_sheet"] == sheet.name


def test_segmenter_worst_images_and_their_sheet(checkpoints, tiny_dataset, tmp_path):
    """A segmenter row lists its test images by their own mIoU, lowest first, as recomputed
    here from a plain forward pass and the confusion-matrix metrics; the row carries the
    worst images' predicted maps, and `handskin evaluate` draws and links the sheet."""
    import typer
    from typer.testing import CliRunner

    from learn.cli import register
    from learn.metrics import confusion_matrix, mean_iou
    from learn.worst import unpack_labels

    ckpt = checkpoints["segnet"]
    row = evaluate_checkpoint(ckpt, tiny_dataset, time_runs=2)
    model, split, test = _model_and_test_split(ckpt, tiny_dataset)
    with torch.no_grad():
        pred = (model(test.x).argmax(1) * (test.x[:, 0] > 0)).numpy()
    y = test.y.numpy()
    miou = [mean_iou(confusion_matrix(y[k], pred[k], 7)) for k in range(len(y))]
    images = row["worst"]["images"]
    assert len(images) == min(len(y), 50)
    np.testing.assert_allclose(
        [w["mean_iou"] for w in images], sorted(miou)[: len(images)], atol=1e-12
    )
    maps = unpack_labels(row["worst"]["maps"])
    assert len(maps) == min(len(y), 9)
    for w, m in zip(images, maps, strict=False):  # each map is its image's prediction
        k = int(np.flatnonzero(split.indices == w["index"])[0])
        assert np.array_equal(m, pred[k]) and miou[k] == pytest.approx(w["mean_iou"], abs=1e-12)
    app = typer.Typer()
    register(app)
    md = tmp_path / "r.md"
    res = CliRunner().invoke(
        app, ["evaluate", str(ckpt), "--data", str(tiny_dataset), "--report", str(md)]
    )
    assert res.exit_code == 0, res.output
    sheet = tmp_path / "r_errors_SegNet.png"
    assert sheet.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert f"![lowest-mIoU test images]({sheet.name})" in md.read_text()
    assert json.loads(md.with_suffix(".json").read_text())[0]["error_sheet"] == sheet.name


def test_report_json_keeps_every_value_and_puts_number_lists_on_one_line():
    from learn.eval_report import report_json

    rows = [
        {
            "cm": [[1, -2], [3e-05, 4.5]],
            "names": ["a", "1"],
            "x": float("nan"),
            "per_image_cm": [[[0, 1], [2, 3]]] * 3,
            "nested": {"v": [1.0, -1e20]},
        }
    ]
    text = report_json(rows)
    back = json.loads(text)
    assert back[0]["x"] != back[0]["x"]  # NaN survives
    back[0]["x"] = rows[0]["x"] = None
    assert back == rows
    assert "[1, -2]" in text and "[3e-05, 4.5]" in text and '"1"' in text
    assert "[1.0, -1e+20]" in text
