"""Fault-aware training data: the train part plus K copies of it with random sensor faults.

    mix = FaultMix()
    data = augmented_data("data/forearm", run, n_train=None, copies=2, mix=mix, seed=0)
    fit(run, data, "models/handsnet_fault_aware", init_from="models/handsnet/best.pt")

Copy c of sample i (train or validation part) draws its faults from
``stream(seed, KEY_COPIES, c, i)``: blind spots, dead modules and gain drift on the pressures
(``tactile.faults``), then, with probability ``p_removal``, one map of a pool of rebuilt maps
with taxels removed (drawn from ``stream(seed, KEY_POOL, j)``, a stream the evaluation never
uses, so no test pattern is seen in training). The image is regenerated through that map
exactly as the evaluation does; the segmentation target is the faulty frame's label image,
background inside the spots, traced onto the rebuilt map (pixels it does not cover are
background). Precomputing the copies keeps ``learn.train.fit`` unchanged (``TensorData``).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from learn.experiments.robustness_data import (
    KEY_COPIES,
    KEY_POOL,
    net_inputs,
    net_labels,
    read_rows,
    stream,
)
from learn.experiments.robustness_maps import RemovedMap, rebuild, spot_pattern, warp_labels
from learn.inputs import input_canvas
from tactile.dataset.reader import DatasetReader
from tactile.errors import ConfigError
from tactile.faults import dead_modules, gain_drift, nested_removal, zero_taxels
from tactile.labels import label_image
from tactile.tactile_map import TactileMap

REMOVAL_FRACTIONS = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7)


@dataclass(frozen=True)
class FaultMix:
    """The random faults of one training copy (each drawn independently).

    p_blind : probability of blind spots; n_spots : (min, max) count; radius_mm : (min, max) mm.
    p_dead : probability of dead modules; dead_modules : (min, max) count (needs module ids).
    p_drift : probability of gain drift; gain_sigma : sd of the log gain (dimensionless).
    p_removal : probability of a map with taxels removed; fractions : shares removed in the
    pool; pool_patterns : nested removal patterns in the pool (each at every fraction).
    """

    p_blind: float = 0.5
    n_spots: tuple[int, int] = (1, 4)
    radius_mm: tuple[float, float] = (10.0, 40.0)
    p_dead: float = 0.25
    dead_modules: tuple[int, int] = (1, 3)
    p_drift: float = 0.5
    gain_sigma: float = 0.2
    p_removal: float = 0.5
    fractions: tuple[float, ...] = REMOVAL_FRACTIONS
    pool_patterns: int = 2

    def __post_init__(self) -> None:
        probs = (self.p_blind, self.p_dead, self.p_drift, self.p_removal)
        if not all(0.0 <= p <= 1.0 for p in probs):
            raise ConfigError(f"FaultMix probabilities must lie in [0, 1], got {probs}")
        if not all(0.0 < f < 1.0 for f in self.fractions) or self.pool_patterns < 1:
            raise ConfigError("FaultMix.fractions must lie in (0, 1), pool_patterns >= 1")


def removal_pool(tmap: TactileMap, layout, mix: FaultMix, seed: int) -> list[RemovedMap]:
    """The rebuilt maps a training copy may be imaged through (pool_patterns x fractions)."""
    if mix.p_removal == 0:
        return []
    pool = []
    for j in range(mix.pool_patterns):
        keeps = nested_removal(tmap.n_taxels, mix.fractions, stream(seed, KEY_POOL, j))
        pool += [rebuild(tmap, layout, k, f) for f, k in zip(mix.fractions, keeps, strict=True)]
    return pool


def faulty_copy(
    p: np.ndarray,
    labels: np.ndarray | None,
    tmap: TactileMap,
    module_ids: np.ndarray | None,
    pool: list[RemovedMap],
    mix: FaultMix,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray | None]:
    """(image (H', W') uint8, label image (H', W') uint8 or None) of one frame p (N,) Pa with
    random faults; ``labels`` (N,) taxel classes, None for classification."""
    spot_px = None
    if rng.random() < mix.p_blind:
        n_spots = int(rng.integers(mix.n_spots[0], mix.n_spots[1] + 1))
        blind, spot_px = spot_pattern(tmap, n_spots, float(rng.uniform(*mix.radius_mm)), rng)
        p = zero_taxels(p, blind)
    if module_ids is not None and rng.random() < mix.p_dead:
        n_dead = int(rng.integers(mix.dead_modules[0], mix.dead_modules[1] + 1))
        p = zero_taxels(p, dead_modules(module_ids, n_dead, rng))
    if rng.random() < mix.p_drift:
        p = gain_drift(p, mix.gain_sigma, rng)[0]
    removed = pool[int(rng.integers(len(pool)))] if pool and rng.random() < mix.p_removal else None
    image = tmap.image(p) if removed is None else removed.tmap.image(p[removed.keep])
    if labels is None:
        return image, None
    truth = label_image(tmap, p, labels, image=tmap.image(p) if removed else image)
    if spot_px is not None:
        truth[spot_px] = 0
    return image, truth if removed is None else warp_labels(truth[None], removed, fill=0)[0]


def faulty_copies(
    path: str | Path,
    ids: np.ndarray,
    task: str,
    size: tuple[int, int],
    copies: int,
    mix: FaultMix,
    seed: int,
    canvas_mm: tuple[float, float] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(x (copies * S, 1, h, w) float32, y (copies * S,) or (copies * S, h, w) int64) of
    dataset samples ``ids`` (S,), copy-major; ``canvas_mm``: the model's input canvas."""
    reader = DatasetReader(path)
    with reader:
        rows = read_rows(reader, ids)
        hand = reader.is_hand[:].astype(np.int64)[ids]
        tmap, layout = reader.map, reader.layout
    pool = removal_pool(tmap, layout, mix, seed)
    segment, canvas = task == "segment", input_canvas(canvas_mm, tmap.step_mm)
    xs, ys = [], []
    for c in range(copies):
        for i, sample in enumerate(ids):
            rng = stream(seed, KEY_COPIES, c, int(sample))
            labels = rows["taxel_label"][i] if segment else None
            image, truth = faulty_copy(
                rows["pressure"][i], labels, tmap, layout.module_ids, pool, mix, rng
            )
            xs.append(net_inputs(image[None], size, task, canvas))
            ys.append(net_labels(truth[None], size, canvas) if segment else hand[i : i + 1])
    if not xs:
        return np.zeros((0, 1, *size), np.float32), np.zeros((0,), np.int64)
    return np.concatenate(xs), np.concatenate(ys)


def augmented_data(
    path: str | Path,
    run,
    n_train: int | None,
    copies: int,
    mix: FaultMix,
    seed: int,
    progress: bool = True,
):
    """``learn.folder.Data``: the (subset of the) train part's stored images followed by
    ``copies`` faulty copies of them, and the validation part likewise, so that the epoch
    kept is the best on clean and faulty images together."""
    from learn.experiments.robustness_models import split_data
    from learn.folder import Data

    if copies < 0:
        raise ConfigError(f"faulty copies must be >= 0, got {copies}")
    data, ids = split_data(path, run, n_train, seed, progress)
    size, canvas = run.model.input_size, run.model.canvas_mm
    train = _with_copies(
        data.train, faulty_copies(path, ids["train"], run.task, size, copies, mix, seed, canvas)
    )
    val = data.val
    if val is not None:
        val = _with_copies(
            val, faulty_copies(path, ids["val"], run.task, size, copies, mix, seed, canvas)
        )
    desc = {
        **data.description,
        "n_train": len(train.y),
        "n_val": 0 if val is None else len(val.y),
        "faulty_copies": copies,
    }
    return Data(train, val, None, data.class_names, desc)


def _with_copies(clean, copies: tuple[np.ndarray, np.ndarray]):
    """TensorData of ``clean`` followed by the copies (x, y) arrays."""
    import torch

    from learn.folder import TensorData

    x, y = copies
    return TensorData(
        torch.cat([clean.x, torch.from_numpy(x)]), torch.cat([clean.y, torch.from_numpy(y)])
    )
