"""`handskin experiment ... --device`: the experiments that train networks train them where the
user asks, refuse an absent GPU before any work, and reuse a network wherever it trained."""

from __future__ import annotations

import dataclasses

import pytest
import torch
import typer
from typer.testing import CliRunner

import learn.train.runs
from experiments.cli import register
from experiments.fault_aware import QUICK_FA, fault_aware_model
from experiments.fidelity import FidelityPlan, probe_run
from experiments.networks import resolve_model
from experiments.settings import QUICK_PLAN, TrainPlan
from experiments.transfer import TransferSettings
from experiments.transfer_runs import finetune_run, pretrain_run
from learn.config import RunConfig

COMMANDS = ("robustness-a", "robustness-b", "fault-aware", "transfer", "fidelity")


@pytest.fixture
def app() -> typer.Typer:
    root = typer.Typer()
    register(root)
    return root


def args_of(command: str, data, out) -> list[str]:
    """Arguments that run ``command`` quickly on ``data``, all valid."""
    first = [] if command == "fidelity" else [str(data)]
    return [*first, "--out", str(out), "--quick", "--no-progress"]


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has a CUDA GPU")
@pytest.mark.parametrize("command", COMMANDS)
@pytest.mark.parametrize(
    ("device", "message"),
    [("cuda", "sees no CUDA GPU. Fix: --device cpu"), ("tpu", "is not a training device")],
)
def test_an_unusable_device_is_refused_before_any_work(
    app, tiny_dataset, tmp_path, command, device, message
):
    out = tmp_path / "out"
    res = CliRunner().invoke(
        app, ["experiment", command, *args_of(command, tiny_dataset, out), "--device", device]
    )
    assert res.exit_code == 2, res.output
    assert message in " ".join(res.output.split()), res.output
    assert not out.exists()


class Trained(Exception):
    """Raised by the recording ``fit`` in place of training."""


@pytest.fixture
def fit_devices(monkeypatch) -> list[str]:
    """A GPU that passes the device check, and ``fit`` recording the device it is asked to
    train on instead of training."""
    monkeypatch.setattr(torch.cuda, "is_available", lambda: True)
    monkeypatch.setattr(torch.cuda, "device_count", lambda: 1)
    seen: list[str] = []

    def record(run, *args, **kwargs):
        seen.append(run.device)
        raise Trained

    monkeypatch.setattr(learn.train.runs, "fit", record)
    return seen


@pytest.mark.parametrize("plan", [TrainPlan(), QUICK_PLAN], ids=["preset", "quick"])
def test_robustness_networks_train_on_the_plans_device(fit_devices, tiny_dataset, tmp_path, plan):
    with pytest.raises(Trained):
        resolve_model(
            "handsnet",
            tiny_dataset,
            tmp_path,
            None,
            dataclasses.replace(plan, device="cuda:0"),
            0,
            False,
        )
    assert fit_devices == ["cuda:0"]


def test_fault_aware_networks_train_on_the_plans_device(
    fit_devices, checkpoints, tiny_dataset, tmp_path
):
    """Whatever device the plain network's own run named."""
    plan = dataclasses.replace(QUICK_FA.eval.plan, device="cuda:0")
    scale = dataclasses.replace(QUICK_FA, eval=dataclasses.replace(QUICK_FA.eval, plan=plan))
    with pytest.raises(Trained):
        fault_aware_model(
            checkpoints["handsnet"],
            tiny_dataset,
            tmp_path / "fa",
            epochs=1,
            n_train=8,
            scale=scale,
            seed=0,
            progress=False,
        )
    assert fit_devices == ["cuda:0"]


def test_transfer_and_fidelity_runs_name_the_device(fit_devices):
    s, model = TransferSettings(device="cuda:0"), RunConfig().model  # HandsNet's preset
    assert pretrain_run(model, s).device == finetune_run(model, s, scratch=True).device == "cuda:0"
    assert pretrain_run(model, TransferSettings()).device == "cpu"
    plan = FidelityPlan(n=8, epochs=1, workers=1, device="cuda:0")
    assert probe_run("handsnet", plan).device == "cuda:0"
