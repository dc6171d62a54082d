"""Models trained once (``learn.train.runs``): reused only when the configuration matches,
wherever they trained; a stopped run is resumed."""

from __future__ import annotations

import pytest
import torch

from learn.config import preset_run
from learn.data.load import load_data
from learn.train.checkpoint import load_checkpoint, save_checkpoint
from learn.train.loop import fit
from learn.train.runs import ensure_model
from tactile.errors import ConfigError


def test_reuse_needs_the_same_configuration(tiny_dataset, tmp_path):
    first = ensure_model("handsnet", tiny_dataset, tmp_path, epochs=1, progress=False)
    stamp = first.stat().st_mtime_ns
    again = ensure_model("handsnet", tiny_dataset, tmp_path, epochs=1, progress=False)
    assert again == first and first.stat().st_mtime_ns == stamp  # reused, not retrained
    with pytest.raises(ConfigError, match=r"another configuration.*--models"):
        ensure_model("handsnet", tiny_dataset, tmp_path, epochs=2, progress=False)
    assert first.stat().st_mtime_ns == stamp  # nothing written over


def test_a_model_of_a_regenerated_dataset_is_not_reused(tiny_writer, tmp_path):
    """A finished model is not reused once its dataset was generated again at the same path with
    other settings (another fingerprint): refused before any work, the model left as it was."""
    import shutil

    data = tiny_writer(tmp_path / "data", list(range(48)))
    first = ensure_model("handsnet", data, tmp_path / "models", epochs=1, progress=False)
    stamp = first.stat().st_mtime_ns
    shutil.rmtree(data)
    tiny_writer(data, list(range(48)), split="greedy")
    with pytest.raises(ConfigError, match=r"fingerprint.*another --out"):
        ensure_model("handsnet", data, tmp_path / "models", epochs=1, progress=False)
    assert first.stat().st_mtime_ns == stamp


def test_an_experiment_model_keeps_its_dataset_fingerprint(tiny_writer, tmp_path):
    """The experiments' shared models (`experiments.networks.resolve_model`) record the dataset's
    fingerprint, so a regenerated dataset is refused there too."""
    import shutil

    from experiments.networks import resolve_model
    from experiments.settings import TrainPlan

    data = tiny_writer(tmp_path / "data", list(range(48)))
    plan = TrainPlan(epochs=1)
    first = resolve_model("handsnet", data, tmp_path / "models", None, plan, 0, False)
    assert load_checkpoint(first)["data"]["fingerprint"] is not None
    shutil.rmtree(data)
    tiny_writer(data, list(range(48)), split="greedy")
    with pytest.raises(ConfigError, match="fingerprint"):
        resolve_model("handsnet", data, tmp_path / "models", None, plan, 0, False)


def test_a_stopped_run_resumes_instead_of_being_reused(tiny_dataset, tmp_path):
    """A model whose training was cut short (here paused after epoch 1 of 2; a killed run
    leaves the same files) is continued to the end, and ends as an uninterrupted run does."""
    run = preset_run("handsnet", epochs=2, seed=0)
    stopped = fit(
        run,
        load_data(tiny_dataset, run, progress=False),
        tmp_path / "a" / "handsnet",
        progress=False,
        stop_after_epoch=1,
    )
    assert stopped.paused and (tmp_path / "a" / "handsnet" / "best.pt").is_file()
    resumed = ensure_model("handsnet", tiny_dataset, tmp_path / "a", epochs=2, progress=False)
    whole = ensure_model("handsnet", tiny_dataset, tmp_path / "b", epochs=2, progress=False)
    a, b = (load_checkpoint(p.parent / "last.pt") for p in (resumed, whole))
    assert a["epoch"] == b["epoch"] == 2 and len(a["history"]) == 2
    assert all(torch.equal(a["model"][k], v) for k, v in b["model"].items())
    stamp = resumed.stat().st_mtime_ns  # finished now: reused as it is
    again = ensure_model("handsnet", tiny_dataset, tmp_path / "a", epochs=2, progress=False)
    assert again == resumed and resumed.stat().st_mtime_ns == stamp


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
