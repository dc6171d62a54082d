"""The 10 Hz press sequences of a handskin dataset (``handskin generate --keep-sequences``) as
network inputs, one item per hand press, its target the action (grasp, twist, push, ...).

    ds = SequenceDataset("data/actions", split="train", size=(34, 50))
    x, y = ds[0]      # x: (FRAMES, 1, 34, 50) float32 in [0, 1], zero after the press; y: int64
    ds.class_names    # the dataset's ``actions`` attribute, index = y

Frame k of a press is read at ``FRAME_PERIOD_S * (k + 1)`` s; its tactile image is the
dataset's own pipeline (`tactile.dataset.DatasetReader.images_from_raw` at that time), resized
as every network input is (`learn.inputs.net_input`). The HDF5 file is opened lazily in each
DataLoader worker (the reader is pickled unopened).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from learn.inputs import input_canvas, net_input
from tactile.dataset.reader import DatasetReader
from tactile.errors import ConfigError, DataError
from tactile.images.resize import NET_SIZE

FRAME_PERIOD_S = 0.1  # s: the skin is read at 10 Hz; frame k is read at (k + 1) x this
#: Frames of every network input: 1.2 s at 10 Hz holds a hand press's 8-12 frames (approach,
#: load, hold, release), zeros after a shorter one; a longer press keeps its first 12.
FRAMES = 12
SEQUENCE_FIELDS = ("seq_raw", "seq_length", "action")
SPLITS = ("train", "test")


def frame_times_s(n: int) -> np.ndarray:
    """(n,) float64 s: when the skin read frames 0..n-1 of a press."""
    return FRAME_PERIOD_S * (np.arange(n) + 1.0)


def frame_images(reader: DatasetReader, raw: np.ndarray) -> np.ndarray:
    """(L, H, W) uint8 tactile images of the frames ``raw`` (L, N) counts of one press: the
    readout at each frame's time (`frame_times_s`), then the map's image, as the dataset's."""
    pressure = reader.pressure_from_raw(raw, frame_times_s(len(raw)))
    return reader.map.image(pressure)


def hand_sides(reader: DatasetReader, indices: np.ndarray) -> np.ndarray:
    """(S,) str, "right", "left" or "" (unknown): the hand that pressed each sample, from its
    contactor JSON (``type`` = ``right_hand`` / ``left_hand``)."""
    if "contactor" not in reader.fields:
        return np.full(len(indices), "", dtype=object)
    kinds = [json.loads(reader.sample_field("contactor", int(i))).get("type", "") for i in indices]
    return np.array([k.removesuffix("_hand") if k.endswith("_hand") else "" for k in kinds], object)


class SequenceDataset(Dataset):
    """The hand presses of one split of a dataset with sequences: frames and action.

    Parameters
    ----------
    path : dataset folder or dataset.h5 (with ``seq_raw``, ``seq_length`` and ``action``).
    split : "train", "test" or None (all samples); only samples with an action (hands) are kept.
    size : (h, w) px of each frame's network input (anti-aliased resize), or None for the map's.
    canvas_mm : (H, W) mm or None (``ModelConfig.canvas_mm``), as `learn.inputs.net_input`.
    frames : T, the frames of every item: zeros after a shorter press, a longer one cut.

    Items: ``(x, y)``, x (T, 1, h, w) float32 in [0, 1], y int64 index into ``class_names``.
    ``lengths`` (S,) int: the frames each item holds (at most T).
    """

    def __init__(
        self,
        path: str | Path,
        split: str | None = "train",
        size: tuple[int, int] | None = NET_SIZE,
        canvas_mm: tuple[float, float] | None = None,
        frames: int = FRAMES,
    ) -> None:
        if split is not None and split not in SPLITS:
            raise ConfigError(f"unknown split {split!r}; choices: train, test, None (all)")
        self.reader = DatasetReader(path)
        self.size, self.frames = size, int(frames)
        with self.reader:
            missing = [f for f in SEQUENCE_FIELDS if f not in self.reader.fields]
            if missing:
                raise DataError(
                    f"{self.reader.path} has no {', '.join(missing)}: action recognition reads "
                    "the press sequences. Fix: generate the dataset with --keep-sequences "
                    "(handskin generate --keep-sequences --hand-fraction 1.0)"
                )
            self.canvas = input_canvas(canvas_mm, self.reader.map.step_mm)
            n = len(self.reader)
            indices = np.arange(n) if split is None else np.asarray(self.reader.splits[split])
            self.indices = indices[self.reader.action[:][indices] >= 0]
            self.class_names = tuple(self.reader.attrs["actions"])
            self.lengths = np.minimum(self.reader.seq_length[:][self.indices], self.frames)

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, j: int) -> tuple[torch.Tensor, torch.Tensor]:
        if not 0 <= j < len(self):
            raise IndexError(f"item {j} out of range for {len(self)} items")
        i = int(self.indices[j])
        x = self.frames_of(i)
        return torch.from_numpy(x)[:, None], torch.tensor(int(self.reader.action[i]))

    def frames_of(self, i: int) -> np.ndarray:
        """(T, h, w) float32 in [0, 1]: sample ``i``'s network inputs, zeros after its press."""
        n = min(int(self.reader.seq_length[i]), self.frames)
        images = frame_images(self.reader, self.reader.seq_raw[i][: max(n, 1)])
        if self.size is not None:
            x = net_input(images, self.size, "classify", self.canvas)
        else:
            x = images.astype(np.float32) / np.float32(255.0)
        out = np.zeros((self.frames, *x.shape[1:]), np.float32)
        out[:n] = x[:n]
        return out
