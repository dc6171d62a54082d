"""`sim.generate.tiny`: a handful of labelled samples in memory, both classes, reproducible — and
the docstring's example pipeline test, run as written. Its speed: benchmarks/bench_generate.py."""

from __future__ import annotations

import numpy as np
import pytest

from sim.generate.tiny import tiny_map, tiny_samples
from tactile.dataset.schema import Dims, validate_sample
from tactile.errors import ConfigError


@pytest.fixture(scope="module")
def samples() -> list[dict]:
    return tiny_samples(n=8, seed=0)


def test_both_classes_valid_sample_dicts(samples: list[dict]) -> None:
    tmap = tiny_map()
    dims = Dims(tmap.n_taxels, *tmap.shape)
    assert len(samples) == 8
    assert {int(s["is_hand"]) for s in samples} == {0, 1}
    for s in samples:
        validate_sample(s, dims)
        assert s["image"].shape == tmap.shape and s["image"].any()
    hands = [s for s in samples if s["is_hand"]]
    assert all(s["label_image"].any() and s["subject_id"] >= 0 for s in hands)


def test_same_seed_same_samples_other_seed_other(samples: list[dict]) -> None:
    again = tiny_samples(n=3, seed=0)
    for a, b in zip(samples[:3], again, strict=True):
        np.testing.assert_array_equal(a["raw"], b["raw"])
    other = tiny_samples(n=1, seed=1)
    assert not np.array_equal(other[0]["raw"], samples[0]["raw"])


def test_bad_arguments_name_the_field() -> None:
    with pytest.raises(ConfigError, match="n = 0 is out of range"):
        tiny_samples(n=0)
    with pytest.raises(ConfigError, match="seed = -1 is out of range"):
        tiny_samples(seed=-1)


def test_docstring_example_pipeline(samples: list[dict]) -> None:
    """The pattern of the module docstring with a trivial 'pipeline': the brightest pixel."""

    def my_pipeline(raw: np.ndarray) -> np.ndarray:
        return tiny_map().image(raw.astype(np.float64) - raw.min())

    for s in samples:
        assert my_pipeline(s["raw"]).shape == s["image"].shape
        assert s["label_image"].max() <= 6
