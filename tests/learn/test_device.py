"""Where a run trains (`RunConfig.device`, `handskin train --device`): the CPU by default; a GPU
named "cuda" or "cuda:N" is checked before any work, and a run may resume on another device
(a checkpoint written on a GPU resumes on the CPU, as a last.pt's tensors load to the CPU)."""

from __future__ import annotations

import dataclasses

import pytest
import torch

from learn.config import RunConfig, replace_train
from learn.data.load import load_data
from learn.train.device import check_device, device_of
from learn.train.loop import fit
from tactile.errors import ConfigError

from .conftest import resume_after_edit


@pytest.mark.parametrize("device", ["cpu", "cuda", "cuda:0", "cuda:12"])
def test_device_names_accepted(device):
    assert RunConfig(device=device).device == device


@pytest.mark.parametrize("device", ["gpu", "CPU", "cuda:", "cuda:x", "mps", ""])
def test_device_names_refused_with_the_fix(device):
    with pytest.raises(ConfigError, match=r"not a training device\. Fix: cpu, cuda or cuda:N"):
        RunConfig(device=device)


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a CUDA GPU")
def test_absent_gpu_refused_before_any_work(tiny_dataset, tiny_run, tmp_path):
    run = dataclasses.replace(tiny_run("handsnet", epochs=1), device="cuda")
    data = load_data(tiny_dataset, dataclasses.replace(run, device="cpu"))
    with pytest.raises(ConfigError, match=r"sees no CUDA GPU\. Fix: --device cpu"):
        fit(run, data, tmp_path / "run", progress=False)
    assert not (tmp_path / "run").exists()


def test_gpu_index_beyond_the_machine_refused(monkeypatch):
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 2)
    check_device("cuda:1")
    with pytest.raises(ConfigError, match=r"has 2 GPU\(s\).*Fix"):
        check_device("cuda:2")


def test_run_resumes_on_another_device(tiny_dataset, tiny_run, tmp_path):
    """A last.pt whose run trained on a GPU resumes on the CPU with the uninterrupted run's
    losses; any other change of configuration is still refused."""
    run = tiny_run("handsnet", epochs=2)
    data = load_data(tiny_dataset, run)
    full, resumed = resume_after_edit(run, data, tmp_path, lambda c: c.update(device="cuda:0"))
    assert [h["train_loss"] for h in resumed.history] == [h["train_loss"] for h in full.history]
    assert device_of(resumed.model) == torch.device("cpu")
    with pytest.raises(ConfigError, match=r"only train\.epochs and device may change"):
        fit(replace_train(run, lr=0.5), data, tmp_path / "cut", resume=True, progress=False)


def test_device_of_a_module_without_tensors_is_the_cpu():
    assert device_of(torch.nn.ReLU()) == torch.device("cpu")
    assert device_of(torch.nn.Linear(2, 2)) == torch.device("cpu")


def test_gpu_toml_is_the_gpu_preset():
    """docs/segnet_gpu.toml over the segnet preset gives learn.config.SEGNET_GPU."""
    from pathlib import Path

    from learn import config as C
    from learn.cli.train import resolve_run

    toml = Path(__file__).resolve().parents[2] / "docs" / "segnet_gpu.toml"
    run = resolve_run("segnet", toml, {"device": "cuda"}, False)
    assert (run.model, run.train, run.device) == (C.SEGNET_GPU.model, C.SEGNET_GPU.train, "cuda")
