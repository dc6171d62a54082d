"""Evaluation: metrics of a known prediction against hand computations, the fast inference path
keeps predictions, checkpoint evaluation and the markdown report beside the paper."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from learn.evaluate import (
    confusion_markdown,
    evaluate_checkpoint,
    evaluate_tensors,
    fast_inference,
    plot_history,
    write_report,
)
from learn.folder import TensorData
from learn.models import create_model


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


def test_segmentation_metrics_by_hand():
    y = torch.tensor([[[0, 0], [1, 2]]])  # (1, 2, 2)
    pred = torch.tensor([[[0, 1], [1, 1]]])
    res = evaluate_tensors(Oracle(True, 3), TensorData(pred.float()[:, None], y), 3)
    # cm = [[1,1,0],[0,1,0],[0,1,0]]; IoU: 1/2, 1/3, 0; t = 2, 1, 1
    assert res.metrics["pixel_accuracy"] == pytest.approx(2 / 4)
    assert res.metrics["mean_accuracy"] == pytest.approx((1 / 2 + 1 + 0) / 3)
    assert res.metrics["mean_iou"] == pytest.approx((1 / 2 + 1 / 3 + 0) / 3)
    assert res.metrics["fw_iou"] == pytest.approx((2 * 1 / 2 + 1 * 1 / 3 + 0) / 4)


@pytest.mark.parametrize("arch", ["handsnet", "segnet"])
def test_fast_inference_keeps_predictions(arch):
    torch.manual_seed(0)
    kw = {"input_size": (32, 48)} if arch == "handsnet" else {"width": 0.125}
    model = create_model(arch, **kw).eval()
    x = torch.rand(4, 1, 32, 48)
    fast = fast_inference(model)
    with torch.no_grad():
        agree = (fast(x).argmax(1) == model(x).argmax(1)).double().mean()
    assert agree >= (1.0 if arch == "handsnet" else 0.999)
    assert fast.num_classes == model.num_classes and fast.task == model.task
    strict = fast_inference(model, bf16=True, min_agreement=1.01)  # impossible: float path
    assert not strict.bf16


def test_evaluate_checkpoint_and_report(checkpoints, tiny_dataset, tmp_path):
    rows = [evaluate_checkpoint(checkpoints[a], tiny_dataset, time_runs=3) for a in checkpoints]
    clf, seg = rows
    assert clf["task"] == "classify" and seg["task"] == "segment" and clf["n_test"] == 16
    assert sum(map(sum, clf["cm"])) == 16 and clf["ms_per_image"]["fast"] > 0
    assert abs(clf["fast_metrics"]["accuracy"] - clf["metrics"]["accuracy"]) <= 0.005
    text = write_report(rows, tmp_path / "report.md", "tiny").read_text()
    for needle in ("paper", "97.81", "12.60", "93.37", "89.17", "63.00", "unknown", "not run",
                   f"{100 * clf['metrics']['accuracy']:.2f}", "% of each true class"):
        assert needle in text, needle


def test_plot_history(tmp_path):
    hist = [{"epoch": 1, "train_loss": 1.0, "val_loss": 0.9, "val_metric": 0.6},
            {"epoch": 2, "train_loss": 0.5, "val_loss": 0.7, "val_metric": 0.8}]  # fmt: skip
    assert plot_history(hist, tmp_path / "c.png").stat().st_size > 1000
