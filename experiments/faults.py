"""Fault-aware training data: the train part plus K copies of it with random sensor faults.

    data = augmented_data("data/forearm", run, n_train=None, copies=2, mix=FaultMix(), seed=0)

Copy c of sample i (train or validation part) draws its faults from
``stream(seed, KEY_COPIES, c, i)``: blind spots, dead modules and gain drift on the pressures
(``tactile.images.faults``), then, with probability ``p_removal``, one map of a pool of rebuilt maps
with taxels removed (drawn from ``stream(seed, KEY_POOL, j)``, a stream the evaluation never
uses, so no test pattern is seen in training). The image is regenerated through that map as
the evaluation does; the segmentation target is the faulty frame's label image, background
inside the spots, traced onto the rebuilt map (pixels it does not cover are background).
"""

from __future__ import annotations

import numpy as np
import torch

from experiments.frames import KEY_COPIES, KEY_POOL, net_inputs, read_rows, stream
from experiments.maps import RemovedMap, rebuild, spot_pattern, warp_labels
from experiments.networks import split_data
from learn.data.load import Data, TensorData
from learn.inputs import input_canvas, net_labels
from tactile.dataset.reader import DatasetReader
from tactile.images.faults import dead_modules, gain_drift, nested_removal, zero_taxels
from tactile.images.labels import label_image
from tactile.images.tactile_map import TactileMap


def removal_pool(tmap: TactileMap, layout, mix, seed: int) -> list[RemovedMap]:
    """The rebuilt maps a training copy may be imaged through (pool_patterns x fractions)."""
    if mix.p_removal == 0:
        return []
    pool = []
    for j in range(mix.pool_patterns):
        keeps = nested_removal(tmap.n_taxels, mix.fractions, stream(seed, KEY_POOL, j))
        pool += [rebuild(tmap, layout, k, f) for f, k in zip(mix.fractions, keeps, strict=True)]
    return pool


def faulty_copy(p, labels, tmap: TactileMap, module_ids, pool, mix, rng: np.random.Generator):
    """(image (H', W') uint8, label image (H', W') uint8 or None) of one frame p (N,) Pa with
    random faults of ``mix`` (a ``FaultMix``); ``labels`` (N,) taxel classes, None for
    classification; ``module_ids`` (N,) or None; ``pool``: :func:`removal_pool`'s maps."""
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


def faulty_copies(path, ids: np.ndarray, run, copies: int, mix, seed: int):
    """(x (copies * S, 1, h, w) float32, y (copies * S,) or (copies * S, h, w) int64) of
    dataset samples ``ids`` (S,), copy-major, as the inputs of ``run``'s network."""
    with DatasetReader(path) as reader:
        pressure, taxel_labels = read_rows(reader, ids)
        hand = reader.is_hand[:].astype(np.int64)[ids]
        tmap, layout = reader.map, reader.layout
    pool = removal_pool(tmap, layout, mix, seed)
    size, segment = run.model.input_size, run.task == "segment"
    canvas = input_canvas(run.model.canvas_mm, tmap.step_mm)
    xs = [np.zeros((0, 1, *size), np.float32)]
    ys = [np.zeros((0, *size) if segment else (0,), np.int64)]
    for c in range(copies):
        for i, sample in enumerate(ids):
            rng = stream(seed, KEY_COPIES, c, int(sample))
            labels = taxel_labels[i] if segment else None
            image, truth = faulty_copy(pressure[i], labels, tmap, layout.module_ids, pool, mix, rng)
            xs.append(net_inputs(image[None], size, run.task, canvas))
            ys.append(net_labels(truth[None], size, canvas) if segment else hand[i : i + 1])
    x, y = np.concatenate(xs), np.concatenate(ys).astype(np.int64)
    return torch.from_numpy(x), torch.from_numpy(y)


def augmented_data(
    path, run, n_train: int | None, copies: int, mix, seed: int, progress=True
) -> Data:
    """The (seeded subset of the) train part's stored images followed by ``copies`` faulty
    copies of them, and the validation part likewise, so that the epoch kept is the best on
    clean and faulty images together."""
    data, ids = split_data(path, run, n_train, seed, progress)

    def with_copies(clean: TensorData | None, part: str) -> TensorData | None:
        if clean is None:
            return None
        x, y = faulty_copies(path, ids[part], run, copies, mix, seed)
        return TensorData(torch.cat([clean.x, x]), torch.cat([clean.y, y]))

    train, val = with_copies(data.train, "train"), with_copies(data.val, "val")
    desc = {**data.description, "n_train": len(train.y), "n_val": 0 if val is None else len(val.y)}
    return Data(train, val, None, data.class_names, desc | {"faulty_copies": copies})
