"""docs/common_test_samples.py pairs two report rows on the presses both scored: read from the
datasets the rows were scored on, checked against a loop over the fields read with h5py."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from tactile import TactileMap
from tactile.dataset import DatasetWriter
from tactile.synthetic import cylinder_sector_layout

from .conftest import N_HAND, N_OTHER, make_sample

N = N_HAND + N_OTHER


@pytest.fixture(scope="module")
def script(doc_script):
    return doc_script("common_test_samples")


def write(folder: Path, episode_seed) -> Path:
    """The tiny set with episode seeds ``episode_seed(i)``: two folders of one press plan whose
    seeds differ where a press was redrawn."""
    layout, flat_mm = cylinder_sector_layout(width_mm=60, length_mm=90, pitch_mm=5)
    tmap = TactileMap.build(layout)
    writer = DatasetWriter(
        folder,
        config={"test": "presses"},
        part="sector",
        generator_version="t",
        seed=3,
        tmap=tmap,
        layout=layout,
    )
    rows = [
        {**make_sample(i, tmap, flat_mm), "episode_seed": np.uint64(episode_seed(i))}
        for i in range(N)
    ]
    writer.write_chunk(0, rows)
    writer.merge()
    return folder


@pytest.fixture(scope="module")
def two_skins(tmp_path_factory):
    """(skin A, skin B): B redrew every third press (another episode seed)."""
    root = tmp_path_factory.mktemp("presses")
    return (
        write(root / "a", lambda i: 100 + i),
        write(root / "b", lambda i: 100 + i + (1000 if i % 3 == 0 else 0)),
    )


def keys(folder: Path, i: int) -> tuple[int, int]:
    with h5py.File(folder / "dataset.h5", "r") as f:
        return int(f["samples/episode_seed"][i]), int(f["samples/subject_id"][i])


def reference(a_on: Path, b_on: Path, ia: list[int], ib: list[int]) -> list[int]:
    return [i for i in sorted(set(ia) & set(ib)) if keys(a_on, i) == keys(b_on, i)]


def row(trained_on: Path, scored_on: Path | None, test: list[int]) -> dict:
    out = {"train_data": {"path": str(trained_on)}, "test_indices": test}
    return out if scored_on is None else {**out, "test_data": str(scored_on)}


def test_presses_are_read_from_the_data_each_row_was_scored_on(script, two_skins):
    a, b = two_skins
    ia, ib = list(range(0, N, 2)), list(range(N // 4, N))
    # Two models, each on its own skin: the presses B redrew are not common.
    mine = script.common(row(a, a, ia), row(b, b, ib))
    assert mine.tolist() == reference(a, b, ia, ib)
    assert 0 < len(mine) < len(set(ia) & set(ib))
    # The model trained on A scored on B's data, beside B's own model: every shared index is the
    # same press (both scored on B); reading A's row from its training data would drop a third.
    both_on_b = script.common(row(a, b, ia), row(b, b, ib))
    assert both_on_b.tolist() == reference(b, b, ia, ib) == sorted(set(ia) & set(ib))
    # One model on both skins.
    assert script.common(row(a, a, ia), row(a, b, ib)).tolist() == mine.tolist()


def test_rows_without_test_data_are_read_from_their_training_data(script, two_skins):
    a, b = two_skins
    ia, ib = list(range(N)), list(range(N))
    assert script.common(row(a, None, ia), row(b, None, ib)).tolist() == reference(a, b, ia, ib)
