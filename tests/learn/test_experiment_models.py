"""Experiment models: trained once, reused only when the configuration matches."""

from __future__ import annotations

import pytest
import torch

from learn.checkpoint import load_checkpoint
from learn.experiments.models import ensure_model, preset_run
from learn.train import fit, load_data
from tactile.errors import ConfigError


def test_reuse_needs_the_same_configuration(tiny_dataset, tmp_path):
    first = ensure_model("handsnet", tiny_dataset, tmp_path, epochs=1, progress=False)
    stamp = first.stat().st_mtime_ns
    again = ensure_model("handsnet", tiny_dataset, tmp_path, epochs=1, progress=False)
    assert again == first and first.stat().st_mtime_ns == stamp  # reused, not retrained
    with pytest.raises(ConfigError, match=r"another configuration.*--models"):
        ensure_model("handsnet", tiny_dataset, tmp_path, epochs=2, progress=False)
    assert first.stat().st_mtime_ns == stamp  # nothing written over


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
