"""Fixtures of the experiments' tests: those of tests/learn (the tiny dataset, its trained
checkpoints, fast run configurations), loaded from their file."""

from __future__ import annotations

import importlib.util
from pathlib import Path

_spec = importlib.util.spec_from_file_location(
    "learn_fixtures", Path(__file__).resolve().parents[1] / "learn" / "conftest.py"
)
learn_fixtures = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(learn_fixtures)

checkpoints = learn_fixtures.checkpoints
tiny_dataset = learn_fixtures.tiny_dataset
tiny_run = learn_fixtures.tiny_run
