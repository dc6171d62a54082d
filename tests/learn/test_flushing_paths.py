"""Every CPU pass of a learn/ network runs inside `learn.numerics.flushing`: training and
validation, evaluation, timing, prediction, int8 calibration and the VGG16 features of
VGG16 + SVM. Each convolution records, when it runs, whether the calling thread keeps a
subnormal float (IEEE 754) or flushes it to zero; a pass outside the block would record "kept".
`tests/learn/test_numerics.py` checks the mechanism itself."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from torch import nn

from learn.classical.vgg_svm import extract_features
from learn.data.load import TensorData, load_data
from learn.infer.fastpath import time_per_image
from learn.infer.predict import Predictor
from learn.infer.quantize import int8_supported, quantize_int8
from learn.models import create_model
from learn.train.loop import fit
from learn.train.validation import evaluate_tensors

from .conftest import SIZE, make_run

SUB = np.array([0x100], dtype=np.uint32).view(np.float32)  # a subnormal, from its bits


def _kept() -> bool:
    """True when this thread's arithmetic keeps a subnormal (IEEE 754), False when it flushes."""
    return bool((SUB * np.float32(1)).view(np.uint32)[0])


@pytest.fixture
def conv_states(monkeypatch):
    """The list every Conv2d forward on this thread appends its `_kept` state to."""
    states: list[bool] = []
    real = nn.Conv2d.forward

    def recording(self, x):
        states.append(_kept())
        return real(self, x)

    monkeypatch.setattr(nn.Conv2d, "forward", recording)
    assert _kept()  # the reference: IEEE arithmetic here, so a pass outside can fail the test
    return states


def _images(n: int) -> torch.Tensor:
    return torch.rand(n, 1, *SIZE, generator=torch.Generator().manual_seed(0))


def _ran_flushed(states: list[bool]) -> None:
    assert states, "no convolution ran"
    assert not any(states), f"{sum(states)} of {len(states)} convolutions kept subnormals"
    assert _kept()  # IEEE arithmetic again afterwards
    states.clear()


def test_training_and_validation_flush(conv_states, tiny_dataset):
    run = make_run("handsnet", epochs=1)
    data = load_data(tiny_dataset, run)
    conv_states.clear()  # reading the data runs no network; start counting at training
    fit(run, data, None, progress=False)
    _ran_flushed(conv_states)


@pytest.mark.parametrize("arch", ["handsnet", "segnet"])
def test_evaluation_timing_and_prediction_flush(conv_states, arch):
    n_cls = 2 if arch == "handsnet" else 7
    kw = {"input_size": SIZE} if arch == "handsnet" else {"width": 0.125}
    model = create_model(arch, num_classes=n_cls, **kw).eval()
    x = _images(4)
    y = torch.zeros(4, dtype=torch.int64) if arch == "handsnet" else torch.zeros(4, *SIZE).long()
    evaluate_tensors(model, TensorData(x, y), n_cls)
    _ran_flushed(conv_states)
    time_per_image(model, SIZE, n_warmup=1, n_runs=2)
    _ran_flushed(conv_states)
    task = "classify" if arch == "handsnet" else "segment"
    predictor = Predictor(model, task, SIZE, tuple(str(c) for c in range(n_cls)))
    predictor.logits((255 * np.random.default_rng(0).random((60, 90))).astype(np.uint8))
    _ran_flushed(conv_states)


def test_vgg_features_flush(conv_states):
    model = create_model("vgg16", num_classes=2, width=0.125)
    extract_features(model, _images(3).numpy()[:, 0])
    _ran_flushed(conv_states)


@pytest.mark.skipif(not int8_supported(), reason="this PyTorch build has no oneDNN int8 engine")
def test_int8_calibration_flushes(conv_states):
    model = create_model("handsnet", num_classes=2, input_size=SIZE).eval()
    quantize_int8(model, _images(16))
    _ran_flushed(conv_states)
