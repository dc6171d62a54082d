"""Every real iCub calibration file (both sides, every body part) builds a usable tactile map."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from tactile.geometry.layout import TaxelLayout
from tactile.images.tactile_map import TactileMap

ICUB_FILES = sorted(
    (Path(__file__).resolve().parents[2].parent / "shared/data/icub_skin/positions").glob("*.txt")
)


@pytest.mark.parametrize("path", ICUB_FILES, ids=[p.stem for p in ICUB_FILES])
def test_every_icub_layout_builds_a_flip_free_map(path: Path, icub_positions: Path):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # duplicate positions merged: documented
        layout = TaxelLayout.load(path)
    tmap = TactileMap.build(layout)
    assert tmap.distortion.n_flipped == 0
    placed = np.isfinite(tmap.uv[:, 0])
    assert placed.mean() >= 0.9
    # independent of the code: 2D edge lengths recomputed from uv and 3D positions
    e = np.unique(np.sort(tmap.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0)
    xyz = tmap.positions_m[tmap.vertex_taxel] * 1e3
    ratio = np.linalg.norm(np.diff(tmap.vertex_uv_mm[e], axis=1), axis=2) / np.linalg.norm(
        np.diff(xyz[e], axis=1), axis=2
    )
    assert abs(np.median(ratio) - 1.0) < 0.03
    frame = np.random.default_rng(0).uniform(0, 1, layout.n_taxels)
    img = tmap.image(frame)
    assert img.shape == tmap.shape and img.max() > 0
