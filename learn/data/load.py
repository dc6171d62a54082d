"""Training data in memory: the train (minus a validation part), validation and test splits of a
handskin dataset or an image folder as tensors.

    data = load_data("out/forearm", run)      # Data: train / val / test TensorData, class names
    data.train.x, data.train.y                # (S, 1, h, w) float32 in [0, 1]; (S,) or (S, h, w)

Validation samples are subjects and object instances disjoint from the training ones, as the
test split is (``tactile.dataset.splits``).
"""

from __future__ import annotations

import copy
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import Dataset
from tqdm.auto import tqdm

from learn.data.boxes import BoxFolderDataset
from learn.data.dataset import TorchTactileDataset
from learn.data.folder import HAND_NAMES, FolderDataset
from learn.data.sequences import SequenceDataset
from learn.inputs import mirror_classes
from tactile.dataset.boxes import is_box_folder
from tactile.dataset.reader import DATASET, DatasetReader, open_dataset
from tactile.dataset.splits import split_indices
from tactile.errors import ConfigError, DataError
from tactile.images.labels import CLASS_NAMES


@dataclass
class TensorData:
    """Images ``x`` (S, 1, h, w) (or sequences (S, T, 1, h, w)) float32 in [0, 1] and targets
    ``y`` (S,) or (S, h, w) int64; ``mirror`` (C,) int64, the class each class becomes in a
    mirrored view (`learn.inputs.mirror_classes`), or None."""

    x: torch.Tensor
    y: torch.Tensor
    mirror: torch.Tensor | None = None


@dataclass
class Data:
    """Train / validation / test tensors of one source, its class names and a description."""

    train: TensorData
    val: TensorData | None
    test: TensorData | None
    class_names: tuple[str, ...]
    description: dict[str, object]


def materialize(ds: Dataset, desc: str = "reading", progress: bool = True) -> TensorData:
    """Every item of an un-flipped dataset stacked into memory (a progress bar from 500 items),
    with the mirror pairs of its ``class_names``, if any (`learn.inputs.mirror_classes`)."""
    bar = tqdm(range(len(ds)), desc=desc, leave=False, disable=not progress or len(ds) < 500)
    items = [ds[j] for j in bar]
    if not items:
        raise DataError("a data split is empty. Fix: a larger dataset or a smaller val_fraction")
    mirror = mirror_classes(getattr(ds, "class_names", ()))
    x, y = torch.stack([x for x, _ in items]), torch.stack([y for _, y in items])
    return TensorData(x, y, None if mirror is None else torch.from_numpy(mirror))


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
    ``canvas_mm`` (``ModelConfig.canvas_mm``) needs a dataset, whose map grid is in mm. Task
    "action": the dataset's press sequences (`SequenceDataset`)."""
    if task == "action":
        return SequenceDataset(path, split, size, canvas_mm)
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
    if is_box_folder(path):
        return BoxFolderDataset(path, split, task, size, False, seed=seed)
    return FolderDataset(path, split, task, size, False, hand_classes, seed=seed)


def is_dataset(path: str | Path) -> bool:
    """True for a handskin dataset folder (holding dataset.h5) or a dataset.h5 file."""
    path = Path(path)
    return (path / DATASET).is_file() or (path.is_file() and path.suffix == ".h5")


def fingerprint(path: str | Path) -> str | None:
    """The fingerprint of the handskin dataset at ``path`` (what it was generated from:
    `tactile.dataset.manifest`), None for an image or box folder or a dataset without one."""
    if not is_dataset(path):
        return None
    with open_dataset(path) as ds:
        value = ds.attrs.get("fingerprint")
    return None if value is None else str(value)


def group_ids(ds: Dataset) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray | None]:
    """(class, subject_id, instance_id) per sample of ``ds`` (None where unknown)."""
    if isinstance(ds, FolderDataset | BoxFolderDataset):
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
    if isinstance(ds, FolderDataset | BoxFolderDataset):
        return "greedy"
    return str(ds.reader.attrs.get("split_method", "greedy"))


def validation_split(ds: Dataset, fraction: float, seed: int) -> tuple[Dataset, Dataset | None]:
    """(train, val): subjects and instances disjoint, class-stratified (tactile splits); keyed
    (stream 1, so independent of the test split's draws) when the dataset's split is keyed."""
    if fraction <= 0:
        return ds, None
    cls, subject, instance = group_ids(ds)
    if cls is not None:  # hand / non-hand strata; more classes (image folders): one stratum
        cls = np.asarray(cls) > 0 if cls.max(initial=0) <= 1 else np.zeros(len(cls))
        cls = cls.astype(np.int64)
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
    for ``run`` (a ``learn.config.RunConfig``: task, input size, val_fraction, seed)."""
    path, seed, size = Path(path), run.train.seed, run.model.input_size
    canvas = run.model.canvas_mm
    train_ds = open_split(path, "train", run.task, size, hand_classes, seed, canvas)
    if run.task in ("classify", "both"):
        check_classes(train_ds, path)
    train_ds, val_ds = validation_split(train_ds, run.val_fraction, seed)
    test_ds = (
        open_split(path, "test", run.task, size, hand_classes, seed, canvas) if with_test else None
    )
    names = _class_names(train_ds, run.task)
    desc = {
        "path": str(path),
        "kind": "dataset" if is_dataset(path) else "folder",
        "fingerprint": fingerprint(path),
        "hand_classes": None if hand_classes is None else list(hand_classes),
        "n_train": len(train_ds),
        "n_val": _len(val_ds),
        "n_test": _len(test_ds),
    }
    val = None if val_ds is None else materialize(val_ds, "val", progress)
    test = None if test_ds is None else materialize(test_ds, "test", progress)
    train = materialize(train_ds, "train", progress)
    return Data(train, val, test, names, desc)


def check_classes(ds: Dataset, path: Path) -> None:
    """DataError when the train split of ``path`` holds fewer than two classes: a classifier
    trained on one class answers it always, and scores 100 % on a test split like it."""
    cls = group_ids(ds)[0]
    present = np.unique(cls) if cls is not None and len(cls) else np.zeros(0)
    if len(present) < 2:
        names = ds.class_names if isinstance(ds, FolderDataset | BoxFolderDataset) else HAND_NAMES
        held = ", ".join(names[int(c)] for c in present) or "no sample"
        raise DataError(
            f"{path}: its train split holds {held} only; a classifier needs two classes or more. "
            "Fix: a dataset with hands and non-hands (handskin generate), or image folders of "
            "two classes or more (--hand-classes names the hand ones)"
        )


def _len(ds: Dataset | None) -> int:
    return 0 if ds is None else len(ds)


def _class_names(ds: Dataset, task: str) -> tuple[str, ...]:
    if task in ("segment", "both"):
        return CLASS_NAMES
    return ds.class_names if isinstance(ds, FolderDataset | SequenceDataset) else HAND_NAMES
