"""docs/check_sensed_share.py re-simulates a dataset's presses exactly as the generator made
them (checked against the stored force and class) and refuses a dataset it cannot reproduce."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from sim.gen_config import load_generate_config
from sim.generate import generate
from tactile.dataset import open_dataset

SMALL = {
    "part": "plate",
    "n": 6,
    "chunk_size": 3,
    "n_subjects": 3,
    "instances_per_kind": 2,
    "duration_scale": 0.5,
    "seed": 11,
    "episode": {"max_attempts": 20},
}


@pytest.fixture(scope="module")
def script(doc_script):
    return doc_script("check_sensed_share")


@pytest.fixture(scope="module")
def plate_dataset(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("sensed") / "ds"
    generate(load_generate_config(None, **SMALL), out, workers=1, progress=False)
    return out


def test_resimulation_matches_the_dataset(script, plate_dataset):
    hand, active, share, force = script.shares(plate_dataset, 10)  # n clipped to the 6 samples
    ds = open_dataset(plate_dataset)
    assert np.array_equal(hand, ds.is_hand[:].astype(bool))
    assert np.array_equal(np.float32(force), ds["force_n"][:])
    assert (active > 0).all() and np.isfinite(share).all() and (share >= 0).all()


def test_a_dataset_it_cannot_reproduce_is_refused(script, plate_dataset, tmp_path):
    copy = tmp_path / "ds"
    copy.mkdir()
    for name in ("dataset.h5", "info.json", "manifest.json"):
        (copy / name).write_bytes((plate_dataset / name).read_bytes())
    with h5py.File(copy / "dataset.h5", "r+") as f:
        f["samples/force_n"][2] += 1.0
    with pytest.raises(SystemExit, match="differ from force_n"):
        script.shares(copy, 6)


def test_a_dataset_with_a_size_filter_is_reproduced(script, tmp_path):
    """The redrawn attempts of `episode.min_active_taxels` are followed: every force matches."""
    out = tmp_path / "ds"
    cfg = SMALL | {"episode": {"max_attempts": 40, "min_active_taxels": 25}}
    generate(load_generate_config(None, **cfg), out, workers=1, progress=False)
    assert open_dataset(out).attrs["rejects"]["few_taxels"] > 0
    _, active, _, force = script.shares(out, 6)
    assert (active >= 25).all()
    assert np.array_equal(np.float32(force), open_dataset(out)["force_n"][:])
