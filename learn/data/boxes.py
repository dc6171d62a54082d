"""A folder of real box-labelled prints (`tactile.dataset.boxes`; ``handskin ingest-boxes``) as
a torch dataset, like a handskin dataset's: every print is a hand; a segmenter's targets are
its box-derived labels (`tactile.dataset.boxes.box_labels`: `IGNORE` where no box says).

    ds = BoxFolderDataset("data/real1", None, "segment", (68, 100), flips=False)
    x, y = ds[0]          # (1, 68, 100) float32 in [0, 1]; (68, 100) int64, 255 = ignored
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset

from learn.data.folder import HAND_NAMES, _split
from learn.inputs import PAPER_VIEWS, flip_view, net_input, net_labels
from tactile.dataset.boxes import BoxFolder, box_labels
from tactile.images.labels import CLASS_NAMES


class BoxFolderDataset(Dataset):
    """Prints of a box folder as ``(image (1, h, w) float32 in [0, 1], target)``: classify ->
    1 (hand, of `HAND_NAMES`); segment -> (h, w) int64 box-derived labels. ``split``: "train",
    "test" (a seeded ``test_fraction`` of the prints) or None (all); ``flips`` triples the
    length (original, columns reversed, rows reversed)."""

    def __init__(
        self,
        root: str | Path,
        split: str | None = None,
        task: str = "segment",
        size: tuple[int, int] = (68, 100),
        flips: bool = True,
        test_fraction: float = 0.3,
        seed: int = 0,
    ) -> None:
        self.folder = BoxFolder.open(root)
        self.task, self.size, self.flips = task, tuple(size), flips
        self.class_names = HAND_NAMES if task == "classify" else CLASS_NAMES
        self.targets = np.ones(len(self.folder), np.int64)
        self.indices = _split(self.targets, split, test_fraction, seed)

    def __len__(self) -> int:
        return len(self.indices) * (len(PAPER_VIEWS) if self.flips else 1)

    def __getitem__(self, j: int) -> tuple[torch.Tensor, torch.Tensor]:
        base, view = divmod(j, len(PAPER_VIEWS)) if self.flips else (j, 0)
        p = self.folder[int(self.indices[base])]
        x = net_input(p.image, self.size, self.task)
        x = torch.from_numpy(flip_view(x, PAPER_VIEWS[view]).copy())[None]
        if self.task == "classify":
            return x, torch.tensor(1, dtype=torch.int64)
        y = net_labels(box_labels(p.image, p.boxes), self.size)
        return x, torch.from_numpy(flip_view(y, PAPER_VIEWS[view]).astype(np.int64))
