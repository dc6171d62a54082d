"""Shared fixtures: the real public data in ../shared/data (never copied into the project)."""

from __future__ import annotations

from pathlib import Path

import pytest

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path of ../shared/data; the test is skipped with the reason when the folder is absent."""
    if not SHARED_DATA.is_dir():
        pytest.skip(f"real public data not found at {SHARED_DATA} (see the brief: ../shared/data)")
    return SHARED_DATA


@pytest.fixture(scope="session")
def icub_positions(shared_data: Path) -> Path:
    """Folder of the real iCub calibration files (positions/*.txt)."""
    path = shared_data / "icub_skin" / "positions"
    if not path.is_dir():
        pytest.skip(f"iCub skin layouts not found at {path}")
    return path
