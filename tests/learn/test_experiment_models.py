"""Experiment models: trained once, reused only when the configuration matches."""

from __future__ import annotations

import pytest

from learn.experiments.models import ensure_model
from tactile.errors import ConfigError


def test_reuse_needs_the_same_configuration(tiny_dataset, tmp_path):
    first = ensure_model("handsnet", tiny_dataset, tmp_path, epochs=1, progress=False)
    stamp = first.stat().st_mtime_ns
    again = ensure_model("handsnet", tiny_dataset, tmp_path, epochs=1, progress=False)
    assert again == first and first.stat().st_mtime_ns == stamp  # reused, not retrained
    with pytest.raises(ConfigError, match=r"another configuration.*--models"):
        ensure_model("handsnet", tiny_dataset, tmp_path, epochs=2, progress=False)
    assert first.stat().st_mtime_ns == stamp  # nothing written over
