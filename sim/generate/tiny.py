"""Labelled synthetic contacts in memory, in seconds: for a downstream project's own CI.

`tiny_samples` runs the real generator (same episode runner, hands and non-hands, same sample
dicts as a dataset's) on the small flat `plate` part (384 taxels, a 136 x 171 px map) with a few
subjects and object instances and half-length presses, without writing files. Sample ``i``
depends only on ``(seed, i)``; both classes appear once ``n >= 3``.

Example (a pytest test of your own touch pipeline)::

    from sim.generate.tiny import tiny_samples

    def test_my_classifier_runs_on_synthetic_touches():
        samples = tiny_samples(n=8, seed=0)          # ~1-2 s on one core, after imports
        for s in samples:
            image = s["image"]                       # (H, W) uint8 tactile image
            raw = s["raw"]                           # (N,) uint16 skin readings, counts
            is_hand = bool(s["is_hand"])             # ground truth: hand (1) or not (0)
            parts = s["label_image"]                 # (H, W) uint8 classes 0..6 (CLASS_NAMES)
            assert my_pipeline(raw).shape == ...     # your code here

The keys and units are those of docs/dataset_format.md; `tiny_map()` gives the `TactileMap`
(and ``tiny_map().positions_m`` the taxel positions, m) the images were made with.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from sim.episode.runner import EpisodeConfig
from sim.generate.config import GenerateConfig
from sim.generate.sampler import WorkerState, build_state, sample_at
from tactile.images.tactile_map import TactileMap

TINY_PART = "plate"  # flat 0.2 x 0.2 m plate, 32 modules: the fastest part to build and press
TINY_DURATION_SCALE = 0.5  # half-length approach/load/hold: a few hundred steps per episode
# A hand is sometimes too big for the small plate (no contact): allow more redraws than default.
TINY_MAX_ATTEMPTS = 20


def tiny_config(n: int = 8, seed: int = 0) -> GenerateConfig:
    """The `tiny` preset: plate part, 4 subjects, 2 instances per object kind, short presses."""
    return GenerateConfig(
        part=TINY_PART,
        n=n,
        seed=seed,
        n_subjects=4,
        instances_per_kind=2,
        duration_scale=TINY_DURATION_SCALE,
        chunk_size=max(1, min(n, 4096)),
        episode=EpisodeConfig(max_attempts=TINY_MAX_ATTEMPTS),
    )


@lru_cache(maxsize=4)
def _state(seed: int) -> WorkerState:
    return build_state(tiny_config(1, seed))


def tiny_samples(n: int = 8, seed: int = 0) -> list[dict[str, np.ndarray]]:
    """``n`` labelled samples (dataset sample dicts) of the tiny preset, in memory.

    Returns a list of dicts: ``raw`` (N,) uint16 counts, ``pressure_pa`` (N,) float32 Pa,
    ``image`` / ``label_image`` (H, W) uint8, ``is_hand`` uint8, ``taxel_label`` (N,) uint8,
    ``subject_id``, ``instance_id``, ``contactor`` (JSON str), ``force_n`` N, ``time_s`` s, ...
    Hands are ~48 % (the paper's 1710/3530), interleaved: samples 2, 4, 6 of the first 8.
    """
    tiny_config(n, seed)  # validates n and seed (ConfigError naming the field)
    state = _state(seed)
    return [sample_at(i, state)[0] for i in range(n)]


def tiny_map() -> TactileMap:
    """The `TactileMap` of the tiny preset's part (pixel grid of the images)."""
    return _state(0).ctx.tmap
