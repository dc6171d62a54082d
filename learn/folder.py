"""Training data from disk: a folder of real images, or a handskin dataset, as in-memory tensors.

A folder of images (e.g. TaISLab's ``images/<class>/*.jpg``, 28 × 50 px grey):

    ROOT/[images/]<class>/<name>.{png,jpg,jpeg,bmp}   classification: the folder names the class
    ROOT/labels/[<class>/]<name>.png                   optional segmentation labels: RGB coded
                                                       with tactile.PALETTE, or class-id PNGs

Classes are the sorted folder names, or hand / non-hand with ``hand_classes=("hand", "finger")``.
Folders hold no subjects, so their train/test split is per image, stratified by class and
seeded (``test_fraction``). ``load_data`` reads either kind of source into :class:`Data`.
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from PIL import Image
from torch.utils.data import Dataset
from tqdm.auto import tqdm

from learn.inputs import net_input
from learn.losses import class_pixel_counts, median_frequency_weights
from learn.tta import PAPER_VIEWS, flip_array
from tactile.dataset.reader import DATASET, DatasetReader
from tactile.dataset.splits import split_indices
from tactile.errors import ConfigError, DataError
from tactile.labels import CLASS_NAMES, PALETTE
from tactile.resize import resize_labels

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")
HAND_NAMES = ("non_hand", "hand")


def read_grey(path: Path) -> np.ndarray:
    """An image file as (H, W) uint8 grey levels (colour images are converted)."""
    with Image.open(path) as im:
        return np.asarray(im.convert("L"), dtype=np.uint8)


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
    if not files:
        raise DataError(
            f"no images ({', '.join(IMAGE_SUFFIXES)}) under {root}. Fix: give a "
            "folder with class sub-folders of images"
        )
    return files, [p.parent.name if p.parent != root else "" for p in files]


class FolderDataset(Dataset):
    """Images of a folder as ``(image (1, h, w) float32 in [0, 1], target)``, like
    ``learn.data.TorchTactileDataset`` (``flips`` triples the length: original, columns
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
        x = net_input(read_grey(self.files[i]).astype(np.float32) / 255.0, self.size, self.task)
        x = torch.from_numpy(flip_array(x, PAPER_VIEWS[view]).copy())[None]
        if self.task == "classify":
            return x, torch.tensor(int(self.targets[i]), dtype=torch.int64)
        y = resize_labels(read_label_png(self.label_path(i)), self.size)
        return x, torch.from_numpy(flip_array(y, PAPER_VIEWS[view]).astype(np.int64))


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


@dataclass
class TensorData:
    """Images ``x`` (S, 1, h, w) float32 in [0, 1] and targets ``y`` (S,) or (S, h, w) int64;
    ``types`` (S,) int64 contactor-type ids (`learn.aux_types`) when a run asks for them."""

    x: torch.Tensor
    y: torch.Tensor
    types: torch.Tensor | None = None


@dataclass
class Data:
    """Train / validation / test tensors of one source, its class names and a description."""

    train: TensorData
    val: TensorData | None
    test: TensorData | None
    class_names: tuple[str, ...]
    description: dict[str, object]
    type_names: tuple[str, ...] = ()  # names of ``train.types`` ids, when loaded


def materialize(ds: Dataset, desc: str = "reading", progress: bool = True) -> TensorData:
    """Every item of an un-flipped dataset stacked into memory (a progress bar from 500 items)."""
    bar = tqdm(range(len(ds)), desc=desc, leave=False, disable=not progress or len(ds) < 500)
    items = [ds[j] for j in bar]
    if not items:
        raise DataError("a data split is empty. Fix: a larger dataset or a smaller val_fraction")
    return TensorData(torch.stack([x for x, _ in items]), torch.stack([y for _, y in items]))


def class_weights(y: torch.Tensor, num_classes: int) -> np.ndarray:
    """Median-frequency class weights (C,) of targets (S,) or (S, h, w) (Eigen & Fergus)."""
    if y.ndim >= 2:
        return median_frequency_weights(*class_pixel_counts(y.numpy(), num_classes))
    counts = np.bincount(y.numpy(), minlength=num_classes)
    return median_frequency_weights(counts, np.full(num_classes, counts.sum()))


def open_split(
    path: Path,
    split: str,
    task: str,
    size,
    hand_classes,
    seed: int,
    canvas_mm: tuple[float, float] | None = None,
) -> Dataset:
    """An un-flipped torch dataset of ``split`` from a handskin dataset or an image folder;
    ``canvas_mm`` (``ModelConfig.canvas_mm``) needs a dataset, whose map grid is in mm."""
    from learn.data import TorchTactileDataset

    if is_dataset(path):
        return TorchTactileDataset(
            path, split=split, task=task, size=size, flips=False, canvas_mm=canvas_mm
        )
    if canvas_mm is not None:
        raise ConfigError(
            f"{path} is an image folder, whose pixels have no known size in mm, and the model "
            f"centres its inputs on a {canvas_mm} mm canvas (model.canvas_mm). Fix: ingest the "
            "recordings as a dataset (handskin ingest, with the part's layout), or use a model "
            "without canvas_mm"
        )
    return FolderDataset(path, split, task, size, False, hand_classes, seed=seed)


def is_dataset(path: str | Path) -> bool:
    """True for a handskin dataset folder (holding dataset.h5) or a dataset.h5 file."""
    path = Path(path)
    return (path / DATASET).is_file() or (path.is_file() and path.suffix == ".h5")


def group_ids(ds: Dataset) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """(class, subject_id, instance_id) per sample of ``ds`` (None where unknown)."""
    if isinstance(ds, FolderDataset):
        return ds.targets[ds.indices], None, None
    reader: DatasetReader = ds.reader
    idx = np.sort(ds.indices)
    got = [
        reader[f][idx] if f in reader.fields else None
        for f in ("is_hand", "subject_id", "instance_id")
    ]
    order = np.argsort(np.argsort(ds.indices))
    return tuple(None if g is None else g[order] for g in got)


def subset(ds: Dataset, positions: np.ndarray) -> Dataset:
    """A shallow copy of ``ds`` restricted to ``ds.indices[positions]``."""
    out = copy.copy(ds)
    out.indices = np.asarray(ds.indices)[positions]
    return out


def split_method(ds: Dataset) -> str:
    """The train/test split method of ``ds``'s dataset (``tactile.dataset.splits.METHODS``):
    its ``split_method`` attr, "greedy" for older datasets and image folders."""
    if isinstance(ds, FolderDataset):
        return "greedy"
    return str(ds.reader.attrs.get("split_method", "greedy"))


def validation_split(ds: Dataset, fraction: float, seed: int) -> tuple[Dataset, Dataset | None]:
    """(train, val): subjects and instances disjoint, class-stratified (tactile splits); keyed
    (stream 1, so independent of the test split's draws) when the dataset's split is keyed."""
    if fraction <= 0:
        return ds, None
    cls, subject, instance = group_ids(ds)
    if cls is not None:
        cls = (np.asarray(cls) > 0).astype(np.int64) if cls.max(initial=0) <= 1 else None
    split = split_indices(
        cls,
        subject,
        instance,
        train_fraction=1.0 - fraction,
        seed=seed,
        method=split_method(ds),
        stream=1,
    )
    return subset(ds, split.train), subset(ds, split.test)


def load_data(
    path: str | Path,
    run,
    *,
    hand_classes: Sequence[str] | None = None,
    with_test: bool = True,
    progress: bool = True,
) -> Data:
    """Train (minus a subject-disjoint validation part), validation and test tensors of ``path``
    for ``run`` (a ``learn.train.RunConfig``: task, input size, val_fraction, seed)."""
    path, seed, size = Path(path), run.train.seed, run.model.input_size
    canvas = run.model.canvas_mm
    train_ds = open_split(path, "train", run.task, size, hand_classes, seed, canvas)
    train_ds, val_ds = validation_split(train_ds, run.val_fraction, seed)
    test_ds = (
        open_split(path, "test", run.task, size, hand_classes, seed, canvas) if with_test else None
    )
    names = _class_names(train_ds, run.task)
    desc = {
        "path": str(path),
        "kind": "dataset" if is_dataset(path) else "folder",
        "hand_classes": None if hand_classes is None else list(hand_classes),
        "n_train": len(train_ds),
        "n_val": _len(val_ds),
        "n_test": _len(test_ds),
    }
    val = None if val_ds is None else materialize(val_ds, "val", progress)
    test = None if test_ds is None else materialize(test_ds, "test", progress)
    train = materialize(train_ds, "train", progress)
    type_names: tuple[str, ...] = ()
    if run.aux_types_weight:
        train.types, type_names = _types(path, train_ds, train.y)
    return Data(train, val, test, names, desc, type_names)


def _types(path: Path, ds: Dataset, y: torch.Tensor) -> tuple[torch.Tensor, tuple[str, ...]]:
    """Contactor-type ids (S,) of the samples of ``ds`` (classes ``y``) and their names."""
    from learn.aux_types import type_targets

    if not is_dataset(path):
        raise ConfigError(
            f"{path} is an image folder, which records no contactor types. Fix: "
            "aux_types_weight = 0, or train on a handskin dataset"
        )
    ids, names = type_targets(path, np.asarray(ds.indices), y.numpy() == 1)
    return torch.from_numpy(ids), names


def _len(ds: Dataset | None) -> int:
    return 0 if ds is None else len(ds)


def _class_names(ds: Dataset, task: str) -> tuple[str, ...]:
    if task == "segment":
        return CLASS_NAMES
    return ds.class_names if isinstance(ds, FolderDataset) else HAND_NAMES
