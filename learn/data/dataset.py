"""A PyTorch dataset over a handskin dataset file (``tactile.dataset``), with the paper's flips and
optional sensor faults applied on the fly.

    ds = TorchTactileDataset("out/", split="train", task="classify")   # 3x: original, h-, v-flip
    x, y = ds[0]        # x: (1, 68, 100) float32 in [0, 1]; y: int64 class (or (68, 100) labels)
    DataLoader(ds, batch_size=64, shuffle=True, num_workers=2)

The HDF5 file is opened lazily in each DataLoader worker (the reader is pickled unopened).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from learn.inputs import PAPER_VIEWS, flip_view, input_canvas, net_input, net_labels
from tactile.dataset.reader import DatasetReader
from tactile.errors import ConfigError, DataError
from tactile.images.faults import (
    blind_spots,
    dead_modules,
    gain_drift,
    nested_removal,
    stuck_at,
    zero_taxels,
)
from tactile.images.labels import IGNORE
from tactile.images.resize import NET_SIZE
from tactile.images.tactile_map import TactileMap

TASKS = ("classify", "segment", "both")
SPLITS = ("train", "test")
MAP_CACHE = 4  # rebuilt maps (taxel removal) kept per worker

FaultFn = Callable[[np.ndarray, np.random.Generator], np.ndarray]  # (N,) Pa, rng -> (N,) Pa


@dataclass(frozen=True)
class FaultSpec:
    """Sensor faults applied to a sample's pressures (from its raw readings) before imaging.

    blind_spots : (n_spots, radius_mm) — Test A (tactile.images.faults.blind_spots), or None.
    dead_modules : int, whole modules reading zero (needs layout module ids).
    stuck_fraction : float in [0, 1], taxels stuck at a random level in [0, max p].
    gain_sigma : float >= 0, std of the log gain (gain drift).
    removal_fraction : float in [0, 1) — Test B: taxels removed from the skin, the map rebuilt
        from ``layout.subset(kept)``; one draw per dataset (``nested_removal`` with ``seed``).
    seed : int. per_sample : True draws the other faults per sample from
        ``SeedSequence(seed, spawn_key=(i,))`` (same fault for the 3 flips of sample i); False
        draws them once from ``default_rng(seed)`` for every sample.

    Draw order on one generator: blind spots, dead modules, stuck-at, gain drift.
    """

    blind_spots: tuple[int, float] | None = None
    dead_modules: int = 0
    stuck_fraction: float = 0.0
    gain_sigma: float = 0.0
    removal_fraction: float = 0.0
    seed: int = 0
    per_sample: bool = True

    def __post_init__(self) -> None:
        if not 0.0 <= self.removal_fraction < 1.0:
            raise ConfigError(f"removal_fraction must be in [0, 1), got {self.removal_fraction}")

    def rng(self, i: int) -> np.random.Generator:
        """The generator of sample ``i``'s faults."""
        if self.per_sample:
            return np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(int(i),)))
        return np.random.default_rng(self.seed)

    def apply(
        self,
        p: np.ndarray,
        tmap: TactileMap,
        module_ids: np.ndarray | None,
        rng: np.random.Generator,
    ) -> np.ndarray:
        """Faulty pressures (N,) from pressures p (N,) on the full map ``tmap``."""
        if self.blind_spots is not None:
            p = zero_taxels(p, blind_spots(tmap, *self.blind_spots, rng))
        if self.dead_modules:
            if module_ids is None:
                raise ConfigError("dead_modules needs a layout with module ids; this one has none")
            p = zero_taxels(p, dead_modules(module_ids, self.dead_modules, rng))
        if self.stuck_fraction:
            p = stuck_at(p, self.stuck_fraction, rng)[0]
        if self.gain_sigma:
            p = gain_drift(p, self.gain_sigma, rng)[0]
        return np.asarray(p, dtype=np.float64)

    def kept_taxels(self, n_taxels: int) -> np.ndarray | None:
        """Taxels left after removal ((K,) int64), or None without removal."""
        if not self.removal_fraction:
            return None
        rng = np.random.default_rng(self.seed)
        return nested_removal(n_taxels, [self.removal_fraction], rng)[0]


class TorchTactileDataset(Dataset):
    """Tactile images and targets of one split of a dataset.

    Parameters
    ----------
    path : dataset folder or dataset.h5. split : "train", "test" or None (all samples).
    task : "classify" (target: int64 is_hand), "segment" (target: (h, w) int64 classes 0..6) or
        "both" (every sample; target: a hand's label image, a non-hand's all `IGNORE`: its class
        is that, `learn.train.losses.BothLoss`; inputs as a segmenter's).
    size : (h, w) pixels of the returned images (anti-aliased resize; labels nearest), or None
        for the map's (H, W). flips : True triples the length (original, horizontal flip of the
        columns, vertical flip of the rows; item j is view j % 3 of sample j // 3).
    faults : None, a :class:`FaultSpec`, or a callable ``(p (N,) Pa, rng) -> p (N,) Pa`` (rng as
        FaultSpec(per_sample=True, seed=0)). With faults, images (and label images) are
        recomputed from ``raw`` through ``pressure_from_raw``; without, the stored ones are used.
    hand_only : keep only hand samples (``is_hand == 1``). None (default): True for "segment"
        (the paper segments hand images only: a non-hand print has no parts to find), False for
        "classify". Needs the ``is_hand`` field when True.
    canvas_mm : (H, W) mm or None (``ModelConfig.canvas_mm``): each image and label image is
        centred on a canvas of this size (`learn.inputs.net_input`) before the resize to ``size``.

    Items: ``(image, target)``, image (1, h, w) float32 in [0, 1].
    """

    def __init__(
        self,
        path: str | Path,
        split: str | None = "train",
        task: str = "classify",
        size: tuple[int, int] | None = NET_SIZE,
        flips: bool = True,
        faults: FaultSpec | FaultFn | None = None,
        hand_only: bool | None = None,
        canvas_mm: tuple[float, float] | None = None,
    ) -> None:
        if task not in TASKS:
            raise ConfigError(f"unknown task {task!r}; choices: {', '.join(TASKS)}")
        if split is not None and split not in SPLITS:
            raise ConfigError(f"unknown split {split!r}; choices: train, test, None (all)")
        self.reader = DatasetReader(path)
        self.task, self.size, self.flips, self.faults = task, size, flips, faults
        self.hand_only = task == "segment" if hand_only is None else bool(hand_only)
        with self.reader:
            self._check_fields()
            self.canvas = input_canvas(canvas_mm, self.reader.map.step_mm)
            n = len(self.reader)
            indices = np.arange(n) if split is None else np.asarray(self.reader.splits[split])
            if self.hand_only and "is_hand" in self.reader.fields:
                indices = indices[self.reader.is_hand[:][indices] == 1]
            self.indices = indices
        self._maps: dict[bytes, tuple[np.ndarray, TactileMap]] = {}

    def _check_fields(self) -> None:
        need = {
            "classify": ["is_hand"],
            "segment": ["label_image"],
            "both": ["label_image", "is_hand"],
        }[self.task]
        if self.faults is not None and self.task != "classify":
            need += ["taxel_label", "is_hand"]
        missing = [f for f in need if f not in self.reader.fields]
        if missing:
            raise DataError(
                f"{self.reader.path} has no {missing} for task {self.task!r}. Fix: ingest with "
                "--labels/--part-labels, or choose another task"
            )

    def __getstate__(self) -> dict:
        return {**self.__dict__, "_maps": {}}

    def __len__(self) -> int:
        return len(self.indices) * (len(PAPER_VIEWS) if self.flips else 1)

    def __getitem__(self, j: int) -> tuple[torch.Tensor, torch.Tensor]:
        if not 0 <= j < len(self):
            raise IndexError(f"item {j} out of range for {len(self)} items")
        base, view = divmod(j, len(PAPER_VIEWS)) if self.flips else (j, 0)
        i = int(self.indices[base])
        image, labels = self.image_and_labels(i)
        if self.size is not None:
            x = net_input(
                image, self.size, "classify" if self.task == "classify" else "segment", self.canvas
            )
        else:
            x = image.astype(np.float32) / np.float32(255.0)
        x = torch.from_numpy(np.ascontiguousarray(flip_view(x, PAPER_VIEWS[view])))[None]
        if self.task == "classify":
            return x, torch.tensor(int(self.reader.is_hand[i]), dtype=torch.int64)
        if self.size is not None:
            labels = net_labels(labels, self.size, self.canvas)
        if self.task == "both" and not self.reader.is_hand[i]:
            labels = np.full_like(labels, IGNORE)  # a non-hand: its class, no parts to learn
        labels = np.ascontiguousarray(flip_view(labels, PAPER_VIEWS[view]))
        return x, torch.from_numpy(labels.astype(np.int64))

    def image_and_labels(self, i: int) -> tuple[np.ndarray, np.ndarray | None]:
        """Sample i's (H', W') uint8 image and, for segmentation, (H', W') uint8 label image —
        stored, or recomputed through the (possibly rebuilt) map when faults are set."""
        ds = self.reader
        segment = self.task != "classify"
        if self.faults is None:
            return ds.image[i], ds.label_image[i] if segment else None
        keep, tmap = self.faulty_map()
        p = self.pressure(i)[keep]
        if not segment:
            return tmap.image(p), None
        labels = ds.taxel_label[i][keep]
        hand = int(ds.is_hand[i]) == 1
        blank = np.zeros(tmap.shape, np.uint8)
        return tmap.image(p), tmap.label_image(p, labels) if hand else blank

    def pressure(self, i: int) -> np.ndarray:
        """Sample i's pressures (N,) float64, Pa, from its raw readings, faults applied."""
        ds = self.reader
        t = float(ds.time_s[i]) if "time_s" in ds.fields else None
        p = ds.pressure_from_raw(ds.raw[i], t)
        if self.faults is None:
            return p
        if isinstance(self.faults, FaultSpec):
            return self.faults.apply(p, ds.map, ds.layout.module_ids, self.faults.rng(i))
        return np.asarray(self.faults(p, FaultSpec(seed=0).rng(i)), dtype=np.float64)

    def faulty_map(self) -> tuple[np.ndarray, TactileMap]:
        """(kept taxels (K,) int64, map over them): the dataset's map unless taxels are removed."""
        n = len(self.reader.layout.positions_m)
        spec = self.faults if isinstance(self.faults, FaultSpec) else None
        keep = None if spec is None else spec.kept_taxels(n)
        if keep is None:
            return np.arange(n), self.reader.map
        key = keep.tobytes()
        if key not in self._maps:
            if len(self._maps) >= MAP_CACHE:
                self._maps.pop(next(iter(self._maps)))
            sub = self.reader.layout.subset(keep)
            self._maps[key] = (keep, TactileMap.build(sub, step_mm=self.reader.map.step_mm))
        return self._maps[key]
