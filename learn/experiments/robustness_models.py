"""Networks for the robustness experiments: a given checkpoint, or one trained here and reused.

    plan = QUICK_PLAN                 # few epochs on a seeded subset of the train split
    clf = resolve_model("handsnet", "data/forearm", out / "models", None, plan, seed=0)

With the full plan a missing network is trained by ``learn.experiments.models.ensure_model``
(the preset, hours on a CPU); other plans train on a seeded subset of the train split into
``models_dir/<arch><suffix>``. Either way a folder that already holds ``best.pt`` is reused.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from learn.experiments.robustness_data import KEY_SUBSET, stream
from tactile.errors import ConfigError

SEG_ARCHS = ("segnet", "fcn16s")


@dataclass(frozen=True)
class TrainPlan:
    """How a network missing from the command line is trained.

    epochs : int or None (the preset's). n_train : train-split samples used by the
    classifier, a seeded subset (None: all); seg_n_train : the same for the segmenter (None:
    all). flips : the paper's threefold flip augmentation. seg_width : channel multiplier
    of the segmenter (None: the preset's). input_size : (h, w) px (None: preset). suffix :
    appended to the model folder name, so plans never reuse each other's networks. device :
    where they train ("cpu", "cuda", "cuda:N"; checked with the other inputs, before any work,
    by ``robustness_setup.check_inputs``); a network already trained is reused wherever it
    trained.
    """

    epochs: int | None = None
    n_train: int | None = None
    seg_n_train: int | None = None
    flips: bool = True
    seg_width: float | None = None
    input_size: tuple[int, int] | None = None
    suffix: str = ""
    device: str = "cpu"

    def __post_init__(self) -> None:
        if self.epochs is not None and self.epochs < 1:
            raise ConfigError(f"training epochs must be >= 1, got {self.epochs}")
        if min(n for n in (self.n_train, self.seg_n_train, 2) if n is not None) < 2:
            raise ConfigError(
                f"training samples must be >= 2, got {self.n_train}, {self.seg_n_train}"
            )

    def samples(self, arch: str) -> int | None:
        """Train samples used for ``arch`` (None: all)."""
        return self.seg_n_train if arch in SEG_ARCHS else self.n_train


FULL_PLAN = TrainPlan()
#: A few minutes on 2 free cores: the presets' first 2 epochs, HandsNet on the whole train
#: part (it leaves chance level in about one such epoch; on 1000 samples it had not after 4),
#: SegNet on 600 samples.
QUICK_PLAN = TrainPlan(epochs=2, n_train=None, seg_n_train=600, suffix="_quick")


def plan_run(arch: str, plan: TrainPlan, seed: int):
    """The arch's preset RunConfig changed as ``plan`` says."""
    from learn.experiments.models import preset_run

    run = preset_run(arch, epochs=plan.epochs, seed=seed, device=plan.device)
    model = run.model
    if plan.seg_width is not None and arch in SEG_ARCHS:
        model = dataclasses.replace(model, width=plan.seg_width)
    if plan.input_size is not None:
        model = dataclasses.replace(model, input_size=tuple(plan.input_size))
    return dataclasses.replace(run, model=model, flips=plan.flips)


def split_data(path: str | Path, run, n_train: int | None, seed: int, progress: bool = True):
    """(Data with train and validation tensors, {"train": (S,), "val": (V,)} int64 dataset ids
    of their rows).

    The validation part is the subject-disjoint one of ``learn.folder.load_data``; with
    ``n_train`` the train part is a seeded subset of that size and the validation part is cut
    to at most a quarter of it.
    """
    from learn.folder import Data, materialize, open_split, subset, validation_split

    train_ds = open_split(
        Path(path),
        "train",
        run.task,
        run.model.input_size,
        None,
        run.train.seed,
        run.model.canvas_mm,
    )
    train_ds, val_ds = validation_split(train_ds, run.val_fraction, run.train.seed)
    rng = stream(seed, KEY_SUBSET, 1)
    if n_train is not None and n_train < len(train_ds.indices):
        train_ds = subset(train_ds, np.sort(rng.choice(len(train_ds.indices), n_train, False)))
        if val_ds is not None and len(val_ds.indices) > max(n_train // 4, 1):
            n_val = max(n_train // 4, 1)
            val_ds = subset(val_ds, np.sort(rng.choice(len(val_ds.indices), n_val, False)))
    names = ("non_hand", "hand") if run.task == "classify" else _seg_names()
    desc = {
        "path": str(path),
        "kind": "dataset",
        "n_train": len(train_ds),
        "n_val": 0 if val_ds is None else len(val_ds),
        "n_test": 0,
    }
    val = None if val_ds is None else materialize(val_ds, "val", progress)
    data = Data(materialize(train_ds, "train", progress), val, None, names, desc)
    ids = {
        "train": np.asarray(train_ds.indices, dtype=np.int64),
        "val": np.asarray([] if val_ds is None else val_ds.indices, dtype=np.int64),
    }
    return data, ids


def _seg_names() -> tuple[str, ...]:
    from tactile.labels import CLASS_NAMES

    return tuple(CLASS_NAMES)


def resolve_model(
    arch: str,
    data: str | Path,
    models_dir: str | Path,
    checkpoint: str | Path | None,
    plan: TrainPlan,
    seed: int,
    progress: bool = True,
) -> Path:
    """Path of a checkpoint of ``arch``: the given one, or one trained as ``plan`` says."""
    from learn.experiments.models import ensure_model, train_once

    if checkpoint is not None or dataclasses.replace(plan, device=FULL_PLAN.device) == FULL_PLAN:
        return ensure_model(
            arch,
            data,
            models_dir,
            checkpoint=checkpoint,
            seed=seed,
            progress=progress,
            device=plan.device,
        )
    out, run = Path(models_dir) / f"{arch}{plan.suffix}", plan_run(arch, plan, seed)
    return train_once(
        out,
        run,
        lambda: split_data(data, run, plan.samples(arch), seed, progress)[0],
        progress=progress,
    )[0]
