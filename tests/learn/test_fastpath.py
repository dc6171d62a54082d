"""The fast inference path: it keeps eval mode's predictions, bf16 only where it flips no clear
decision, and fp32 when its test accuracy strays from eval mode's."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from learn.data.load import TensorData
from learn.evaluate.scoring import scored_fast_path
from learn.infer.fastpath import clear_disagreements, fast_inference
from learn.models import create_model


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


class _Logits(nn.Module):
    """Returns the given logits ``(N, C[, H, W])`` whatever the input."""

    def __init__(self, logits: torch.Tensor) -> None:
        super().__init__()
        self.logits = logits

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.logits


def test_clear_disagreements_leaves_out_near_ties():
    # float reference b: image 0 clear (p 0.88 / 0.12), image 1 a near tie, image 2 clear
    b = _Logits(torch.tensor([[2.0, 0.0], [0.0, 0.01], [0.0, 3.0]]))
    a = _Logits(torch.tensor([[0.0, 2.0], [0.01, 0.0], [0.0, 3.0]]))  # flips images 0 and 1
    assert clear_disagreements(a, b, torch.zeros(3), tie_gap=0.02) == 1
    assert clear_disagreements(a, b, torch.zeros(3), tie_gap=0.0) == 2
    assert clear_disagreements(a, b, torch.zeros(3), tie_gap=0.9) == 0  # 0.76 gap counts as a tie
    seg = torch.zeros(1, 3, 2, 2)  # per pixel: one clear flip, one near-tie flip
    seg[0, 0, 0, 0], seg[0, 1, 0, 1], seg[0, 2, 1, :] = 5.0, 5.0, 1.0
    seg_a = seg.clone()
    seg_a[0, :, 0, 0] = torch.tensor([0.0, 5.0, 0.0])
    seg_a[0, :, 1, 0] = torch.tensor([0.0, 1.0, 1.001])
    seg[0, :, 1, 0] = torch.tensor([0.0, 1.001, 1.0])
    assert clear_disagreements(_Logits(seg_a), _Logits(seg), seg, tie_gap=0.02) == 1


def test_bf16_turned_off_where_it_flips_a_clear_decision():
    """Two output rows 0.3 % apart (bfloat16 keeps 8 bits: both round to 1.0): on an image of
    1,000 ones float32 says class 1 by a logit of 3, bf16 ties and argmax says class 0."""
    model = nn.Sequential(nn.Flatten(), nn.Linear(1000, 2, bias=False))
    with torch.no_grad():
        model[1].weight[0], model[1].weight[1] = 1.0, 1.003
    x = torch.ones(1, 1, 25, 40)
    assert model(x).argmax(1).item() == 1
    assert not fast_inference(model, bf16=True, check=x).bf16
    assert fast_inference(model, bf16=True, check=torch.zeros_like(x)).bf16  # a tie: kept


def test_bf16_kept_over_a_near_tie():
    """A HandsNet whose check image 0 is a near tie keeps bf16, and bf16 agrees with the
    unprepared float model on every image the latter decides clearly."""
    torch.manual_seed(0)
    model = create_model("handsnet", input_size=(32, 48)).eval()
    x = torch.rand(8, 1, 32, 48)
    with torch.no_grad():  # make image 0 a near tie: its two logits 1e-4 apart
        logits = model(x)
        model.classifier[-1].bias += torch.tensor([0.0, float(logits[0, 0] - logits[0, 1]) + 1e-4])
        ref = model(x).softmax(1)
    assert abs(float(ref[0, 1] - ref[0, 0])) < 1e-3
    fast = fast_inference(model, bf16=True, check=x)
    assert fast.bf16
    with torch.no_grad():
        agree = fast(x).argmax(1) == ref.argmax(1)
    assert bool(agree[(ref[:, 1] - ref[:, 0]).abs() >= 0.02].all())


def test_the_fast_path_falls_back_to_fp32_when_its_accuracy_strays():
    """A fast path 0.5 points or more off eval mode's accuracy is rebuilt in fp32 (``bf16=False``)
    and scored again; without a reference accuracy the first build is kept."""
    torch.manual_seed(0)
    x = torch.randn(200, 1, 8, 8)
    model = nn.Sequential(nn.Flatten(), nn.Linear(64, 2)).eval()
    y = model(x).argmax(1)  # eval mode is right on every image
    test = TensorData(x, y)
    flipped = nn.Sequential(nn.Flatten(), nn.Linear(64, 2)).eval()  # a "bf16" path, always wrong
    with torch.no_grad():
        flipped[1].weight.copy_(-model[1].weight)
        flipped[1].bias.copy_(-model[1].bias)
    builds = []

    def make(**kw):
        builds.append(kw)
        return model if kw.get("bf16") is False else flipped

    fast, res = scored_fast_path(make, test, 2, ref_accuracy=1.0)
    assert fast is model and res.metrics["accuracy"] == 1.0
    assert builds[0].keys() == {"check"} and builds[1] == {"bf16": False}
    builds.clear()
    fast, res = scored_fast_path(make, test, 2)
    assert fast is flipped and res.metrics["accuracy"] == 0.0 and len(builds) == 1
