"""A folder of images as a torch dataset, like a handskin dataset's (``learn.data.dataset``).

A folder of images (e.g. TaISLab's ``images/<class>/*.jpg``, 28 × 50 px grey):

    ROOT/[images/]<class>/<name>.{png,jpg,jpeg,bmp}   classification: the folder names the class
    ROOT/labels/[<class>/]<name>.png                   optional segmentation labels: RGB coded
                                                       with tactile.PALETTE, or class-id PNGs

Classes are the sorted folder names, or hand / non-hand with ``hand_classes=("hand", "finger")``.
Folders hold no subjects, so their train/test split is per image, stratified by class and
seeded (``test_fraction``).
"""

from __future__ import annotations

import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from PIL import Image
from torch.utils.data import Dataset

from learn.inputs import PAPER_VIEWS, flip_view, net_input
from tactile.errors import DataError
from tactile.images.labels import CLASS_NAMES, PALETTE
from tactile.images.resize import resize_labels

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")
HAND_NAMES = ("non_hand", "hand")


def read_grey(path: Path) -> np.ndarray:
    """An image file as (H, W) uint8 grey levels (colour images are converted); DataError
    naming the file when it is not an image or is cut short."""
    try:
        with Image.open(path) as im:
            return np.asarray(im.convert("L"), dtype=np.uint8)
    except (OSError, SyntaxError, ValueError) as err:  # PIL's errors for broken files
        raise DataError(f"{path} is not a readable image ({err}). Fix: give a PNG/JPG/BMP") from err


def read_label_png(path: Path) -> np.ndarray:
    """(H, W) uint8 class ids from a palette-coded RGB PNG or a class-id (grey) PNG."""
    with Image.open(path) as im:
        arr = np.asarray(im.convert("RGB") if im.mode in ("RGB", "RGBA", "P") else im.convert("L"))
    if arr.ndim == 2:
        ids = arr.astype(np.int64)
    else:
        match = np.all(arr[:, :, None, :] == PALETTE[None, None], axis=-1)
        if not match.any(-1).all():
            raise DataError(
                f"{path}: colours outside tactile.PALETTE. Fix: colour the labels "
                "with tactile.colorize or save class ids as a grey PNG"
            )
        ids = match.argmax(-1)
    if ids.max(initial=0) >= len(CLASS_NAMES):
        raise DataError(f"{path}: class ids must lie in 0..{len(CLASS_NAMES) - 1}")
    return ids.astype(np.uint8)


def list_images(root: Path) -> tuple[list[Path], list[str]]:
    """Image files under ``root`` (class sub-folders, or flat) and their folder names."""
    files = sorted(p for p in root.rglob("*") if p.suffix.lower() in IMAGE_SUFFIXES)
    bad = [p for p in files if not _readable(p)]
    if bad:
        shown = ", ".join(str(p.relative_to(root)) for p in bad[:10])
        more = f" and {len(bad) - 10} more" if len(bad) > 10 else ""
        warnings.warn(
            f"{len(bad)} of {len(files)} image files under {root} are not readable images "
            f"(not an image, or cut short) and are skipped: {shown}{more}",
            stacklevel=3,
        )
        files = [p for p in files if p not in set(bad)]
    if not files:
        raise DataError(
            f"no readable images ({', '.join(IMAGE_SUFFIXES)}) under {root}. Fix: give a "
            "folder with class sub-folders of images"
        )
    return files, [p.parent.name if p.parent != root else "" for p in files]


def _readable(path: Path) -> bool:
    """True when ``path`` decodes as an image to its last byte."""
    try:
        with Image.open(path) as im:
            im.load()
        return True
    except (OSError, SyntaxError, ValueError):
        return False


class FolderDataset(Dataset):
    """Images of a folder as ``(image (1, h, w) float32 in [0, 1], target)``, like
    ``learn.data.dataset.TorchTactileDataset`` (``flips`` triples the length: original, columns
    reversed, rows reversed). Targets: int64 class (classify) or (h, w) int64 (segment).

    hand_classes : folder names that count as hand (then classes are non_hand / hand), or None
    to keep every folder as its own class. split : "train", "test" or None; the split is per
    image, stratified by class, ``test_fraction`` of each class to test, seeded by ``seed``.
    """

    def __init__(
        self,
        root: str | Path,
        split: str | None = "train",
        task: str = "classify",
        size: tuple[int, int] = (68, 100),
        flips: bool = True,
        hand_classes: Sequence[str] | None = None,
        test_fraction: float = 0.3,
        seed: int = 0,
    ) -> None:
        root = Path(root)
        if not root.is_dir():
            raise DataError(f"no image folder at {root}. Fix: give an existing folder")
        self.image_root = root / "images" if (root / "images").is_dir() else root
        self.label_root = root / "labels"
        self.files, folders = list_images(self.image_root)
        self.task, self.size, self.flips = task, tuple(size), flips
        self.class_names, self.targets = _classes(folders, hand_classes, self.image_root)
        if task == "segment" and not self.label_root.is_dir():
            raise DataError(f"segmentation needs label PNGs in {self.label_root}")
        self.indices = _split(self.targets, split, test_fraction, seed)

    def __len__(self) -> int:
        return len(self.indices) * (len(PAPER_VIEWS) if self.flips else 1)

    def label_path(self, i: int) -> Path:
        """The label PNG of image ``i``: ``labels/<same relative path>.png``."""
        rel = self.files[i].relative_to(self.image_root).with_suffix(".png")
        return self.label_root / rel

    def __getitem__(self, j: int) -> tuple[torch.Tensor, torch.Tensor]:
        base, view = divmod(j, len(PAPER_VIEWS)) if self.flips else (j, 0)
        i = int(self.indices[base])
        x = net_input(read_grey(self.files[i]), self.size, self.task)
        x = torch.from_numpy(flip_view(x, PAPER_VIEWS[view]).copy())[None]
        if self.task == "classify":
            return x, torch.tensor(int(self.targets[i]), dtype=torch.int64)
        y = resize_labels(read_label_png(self.label_path(i)), self.size)
        return x, torch.from_numpy(flip_view(y, PAPER_VIEWS[view]).astype(np.int64))


def _classes(folders: list[str], hand_classes: Sequence[str] | None, root: Path):
    """(class names, (S,) int64 target per image) from folder names."""
    known = sorted(set(folders))
    if hand_classes is None:
        return tuple(known), np.array([known.index(f) for f in folders], np.int64)
    unknown = sorted(set(hand_classes) - set(known))
    if unknown:
        raise DataError(
            f"hand classes {unknown} are not folders of {root}; folders: {', '.join(known)}"
        )
    return HAND_NAMES, np.array([f in hand_classes for f in folders], np.int64)


def _split(targets: np.ndarray, split: str | None, test_fraction: float, seed: int) -> np.ndarray:
    """Sample indices of ``split``: per class, a seeded ``test_fraction`` goes to test."""
    if split is None:
        return np.arange(len(targets))
    rng = np.random.default_rng(seed)
    test = np.zeros(len(targets), bool)
    for c in np.unique(targets):
        members = rng.permutation(np.flatnonzero(targets == c))
        test[members[: round(test_fraction * len(members))]] = True
    return np.flatnonzero(test if split == "test" else ~test)
