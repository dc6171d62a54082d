"""The networks of the robustness experiments: given checkpoints, or trained here and reused.

    rep, prep = start("robustness-a", "data/forearm", "out", QUICK, seed=0)
    prep.models[0].predict(x)          # x (B, 1, h, w) float32 -> (B,) class ids

A network not given is trained as ``scale.plan`` says (``experiments.settings.TrainPlan``) into
``models_dir/<arch><plan.suffix>`` by ``learn.train.runs.train_once``: a finished run there is
reused, a stopped one resumed.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from experiments.frames import KEY_SUBSET, Frames, load_frames, stream
from experiments.options import check_dataset, check_out
from experiments.report import Report
from learn.config import TASK_OF_ARCH, preset_run
from learn.data.load import (
    Data,
    fingerprint,
    materialize,
    open_split,
    subset,
    validation_split,
)
from learn.evaluate.report import ARCH_LABEL
from learn.inputs import input_canvas, unpressed_as_background
from learn.models import prepare_for_inference
from learn.train.checkpoint import load_checkpoint, model_from_checkpoint
from learn.train.device import check_device
from learn.train.runs import train_once
from learn.train.validation import logits_of
from tactile.errors import ConfigError
from tactile.images.labels import CLASS_NAMES

BATCH = 64  # images per forward pass
CLASSES = {"classify": 2, "segment": 7}  # classes the robustness tests score
FLAGS = {"classify": "--classifier", "segment": "--segmenter"}


class Predictor:
    """A trained network as a function of network inputs (B, 1, h, w) -> class ids.

    name : label in tables. task : "classify" or "segment". size : (h, w) px input.
    canvas_mm : the model's input canvas (``ModelConfig.canvas_mm``) or None. fast : predict
    with batch norms folded into the convolutions (``learn.models.prepare_for_inference``; the
    same classes up to float rounding); False: the eval-mode model.
    """

    def __init__(self, name: str, model: torch.nn.Module, run, fast: bool = True) -> None:
        self.name, self.task, self.size = name, run.task, tuple(run.model.input_size)
        self.net = prepare_for_inference(model) if fast else model.eval()
        self.canvas_mm = run.model.canvas_mm
        if run.model.num_classes != CLASSES[self.task]:
            raise ConfigError(
                f"{name}: the robustness tests score {CLASSES[self.task]} classes for the "
                f"{self.task} task; this network has {run.model.num_classes}"
            )

    @classmethod
    def load(cls, name: str, path, fast: bool = True) -> Predictor:
        """The network of a checkpoint (.pt)."""
        model, run = model_from_checkpoint(load_checkpoint(path), where=path)
        return cls(name, model, run, fast)

    def canvas(self, step_mm: float) -> tuple[int, int] | None:
        """(H', W') map pixels of the model's input canvas on a ``step_mm`` grid, or None."""
        return input_canvas(self.canvas_mm, step_mm)

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Class ids: (B,) int64 per image, or (B, h, w) int64 per pixel, background where the
        input is 0."""
        if len(x) == 0:
            return np.zeros((0, *(() if self.task == "classify" else self.size)), np.int64)
        pred = logits_of(self.net, torch.from_numpy(x), BATCH).argmax(1).numpy()
        return pred if self.task == "classify" else unpressed_as_background(pred, x)


def plan_run(arch: str, plan, seed: int):
    """The arch's preset RunConfig changed as ``plan`` (a ``TrainPlan``) says."""
    run = preset_run(arch, epochs=plan.epochs, seed=seed, device=plan.device)
    model = run.model
    if plan.seg_width is not None and run.task == "segment":
        model = dataclasses.replace(model, width=plan.seg_width)
    if plan.input_size is not None:
        model = dataclasses.replace(model, input_size=tuple(plan.input_size))
    return dataclasses.replace(run, model=model, flips=plan.flips)


def split_data(path, run, n_train: int | None, seed: int, progress: bool = True):
    """(Data with train and validation tensors, {"train": (S,), "val": (V,)} int64 dataset ids
    of their rows). The validation part is the subject-disjoint one of ``learn.data.load``;
    with ``n_train`` the train part is a seeded subset of that size and the validation part is
    cut to at most a quarter of it."""
    ds = open_split(Path(path), "train", run.task, run.model.input_size, None, run.train.seed)
    train, val = validation_split(ds, run.val_fraction, run.train.seed)
    rng = stream(seed, KEY_SUBSET, 1)
    if n_train is not None and n_train < len(train.indices):
        train = subset(train, np.sort(rng.choice(len(train.indices), n_train, False)))
        n_val = max(n_train // 4, 1)
        if val is not None and len(val.indices) > n_val:
            val = subset(val, np.sort(rng.choice(len(val.indices), n_val, False)))
    names = ("non_hand", "hand") if run.task == "classify" else CLASS_NAMES
    desc = {"path": str(path), "kind": "dataset", "fingerprint": fingerprint(path)}
    desc |= {"n_train": len(train)}
    desc |= {"n_val": 0 if val is None else len(val), "n_test": 0}
    x_val = None if val is None else materialize(val, "val", progress)
    data = Data(materialize(train, "train", progress), x_val, None, names, desc)
    ids = {"train": train.indices, "val": [] if val is None else val.indices}
    return data, {k: np.asarray(v, dtype=np.int64) for k, v in ids.items()}


def resolve_model(arch: str, data, models_dir, checkpoint, plan, seed: int, progress: bool):
    """Path of a checkpoint of ``arch``: the given one, or one trained as ``plan`` says."""
    if checkpoint is not None:
        return Path(checkpoint)
    out, run = Path(models_dir) / f"{arch}{plan.suffix}", plan_run(arch, plan, seed)

    def make_data() -> Data:
        return split_data(data, run, plan.samples(arch), seed, progress)[0]

    return train_once(out, run, make_data, progress=progress, data=data)[0]


def check_checkpoint(path: Path | None, task: str) -> None:
    """DataError or ConfigError unless ``path`` (None: not given) holds a ``task`` network."""
    arch = None if path is None else load_checkpoint(path)["config"]["model"]["arch"]
    if arch is not None and TASK_OF_ARCH.get(arch) != task:
        archs = ", ".join(a for a, t in TASK_OF_ARCH.items() if t == task)
        raise ConfigError(f"{FLAGS[task]} {path} holds a {arch} network; give one of {archs}")


@dataclass
class Prepared:
    """What a robustness experiment starts from: networks (Predictors, the classifier first),
    a description of each, the test frames, where trained networks are kept, and whether the
    studies show progress bars."""

    models: list[Predictor]
    info: list[dict]
    frames: Frames
    models_dir: Path
    progress: bool


def start(
    name,
    data,
    out,
    scale,
    seed,
    *,
    classifier=None,
    segmenter=None,
    models_dir=None,
    threads=2,
    progress=True,
    **more,
):
    """(the run's Report, its Prepared networks and frames). Every input is checked first
    (the dataset's test split, the folders, the checkpoints' tasks, threads, device); then the
    networks not given are trained as ``scale.plan`` says (the segmenter only when
    ``scale.n_segment``) into ``models_dir`` (default ``out/models``) on ``threads`` CPU
    threads. ``more``: further entries of the report's configuration."""
    if threads < 1:
        raise ConfigError(f"--threads {threads} is out of range; allowed >= 1")
    check_out(out, ("--models", models_dir))
    check_device(scale.plan.device)
    load_frames(check_dataset(data), "test", n_classify=1, n_segment=1)
    check_checkpoint(classifier, "classify")
    check_checkpoint(segmenter, "segment")
    given = {"classifier": classifier, "segmenter": segmenter, "models": models_dir}
    config = {"data": str(data), "scale": dataclasses.asdict(scale), "threads": threads}
    config |= {k: None if v is None else str(v) for k, v in given.items()} | more
    rep = Report(name, out, seed=seed, config=config)
    torch.set_num_threads(threads)
    models_dir = Path(models_dir) if models_dir is not None else Path(out) / "models"
    models, info = [], []
    for arch, ckpt in {"handsnet": classifier, "segnet": segmenter}.items():
        if arch == "segnet" and not scale.n_segment:
            continue
        path = resolve_model(arch, data, models_dir, ckpt, scale.plan, seed, progress)
        stored = load_checkpoint(path)
        name = ARCH_LABEL.get(stored["config"]["model"]["arch"], arch)
        models.append(Predictor.load(name, path))
        info.append({"name": name, "checkpoint": str(path), "given": ckpt is not None})
        info[-1] |= {"epochs": stored["epoch"], "model": stored["config"]["model"]}
    n = {"n_classify": scale.n_classify, "n_segment": scale.n_segment}
    frames = load_frames(data, "test", **n, seed=seed)
    return rep, Prepared(models, info, frames, models_dir, progress)
