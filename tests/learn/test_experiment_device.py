"""`handskin experiment ... --device`: the experiments that train networks train them where the
user asks, refuse an absent GPU before any work, and reuse a network wherever it trained."""

from __future__ import annotations

import dataclasses

import pytest
import torch
import typer
from typer.testing import CliRunner

from handskin.fidelity import FidelityPlan, probe_run
from learn import train as T
from learn.checkpoint import load_checkpoint, save_checkpoint
from learn.experiments.cli import register
from learn.experiments.fault_aware import QUICK_FA, fault_aware_model
from learn.experiments.models import ensure_model
from learn.experiments.robustness_models import FULL_PLAN, QUICK_PLAN, resolve_model
from learn.experiments.transfer_lib import TransferSettings, finetune_run, pretrain_run
from tactile.errors import ConfigError

COMMANDS = ("robustness-a", "robustness-b", "fault-aware", "transfer", "fidelity")


@pytest.fixture
def app() -> typer.Typer:
    root = typer.Typer()
    register(root, extra_modules=("handskin.transfer", "handskin.fidelity"))
    return root


def args_of(command: str, data, out) -> list[str]:
    """Arguments that run ``command`` quickly on ``data``, all valid."""
    if command == "transfer":
        return ["--out", str(out), "--quick", "--no-progress", "--source", str(data)]
    if command == "fidelity":
        return ["--out", str(out), "--quick", "--no-progress"]
    return ["--out", str(out), "--data", str(data), "--quick", "--no-progress"]


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

    monkeypatch.setattr(T, "fit", record)
    return seen


@pytest.mark.parametrize("plan", [FULL_PLAN, QUICK_PLAN], ids=["preset", "quick"])
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
    s, model = TransferSettings(device="cuda:0"), T.RunConfig().model  # HandsNet's preset
    assert pretrain_run(model, s).device == finetune_run(model, s, scratch=True).device == "cuda:0"
    assert pretrain_run(model, TransferSettings()).device == "cpu"
    plan = FidelityPlan(
        n=8, epochs=1, image_px=(34, 50), workers=1, seed=0, segnet=False, device="cuda:0"
    )
    assert probe_run("handsnet", plan).device == "cuda:0"


def test_a_network_trained_on_a_gpu_is_reused_on_the_cpu(tiny_dataset, tmp_path):
    """A models folder filled on a GPU machine serves a CPU rerun as it is; any other change of
    configuration is still refused."""
    first = ensure_model("handsnet", tiny_dataset, tmp_path, epochs=1, progress=False)
    for path in (first, first.parent / "last.pt"):  # as a run with --device cuda:0 writes them
        ckpt = load_checkpoint(path)
        ckpt["config"]["device"] = "cuda:0"
        save_checkpoint(ckpt, path)
    stamp = first.stat().st_mtime_ns
    assert ensure_model("handsnet", tiny_dataset, tmp_path, epochs=1, progress=False) == first
    assert first.stat().st_mtime_ns == stamp
    with pytest.raises(ConfigError, match="another configuration"):
        ensure_model("handsnet", tiny_dataset, tmp_path, epochs=2, progress=False)
