"""The classical baselines of the paper's Table 3 — bag of visual words (`learn.classical.bovw`)
and VGG16 features + linear SVM (`learn.classical.vgg_svm`) — trained, saved, loaded and
evaluated like the networks.

    report = train_classical("bovw", "out/forearm", Path("runs/bovw"))   # runs/bovw/model.npz
    model = load_classical("runs/bovw/model.npz")     # model.predict((S, h, w) images) -> (S,)
    row = evaluate_classical("runs/bovw/model.npz", "out/forearm")   # a row of write_report

A model is one file (`learn.classical.svm`). Images are the split's tactile images resized to
the input size (float in [0, 1]), as the networks see them; there is no validation hold-out
(nothing is tuned).
"""

from __future__ import annotations

import json
import time
from collections.abc import Mapping
from pathlib import Path

import numpy as np
import torch

from learn.classical.bovw import BagOfVisualWords
from learn.classical.svm import CLASSICAL, MODEL_FILE, load_npz, save_npz
from learn.classical.vgg_svm import VggSvmClassifier
from learn.config import BovwConfig, VggSvmConfig
from learn.data.folder import HAND_NAMES
from learn.data.load import materialize, open_split
from learn.evaluate.contacts import contact_scores, split_contacts
from learn.evaluate.real import BATCH, split_non_hands, trained_on, wilson
from learn.infer.fastpath import check_timing
from learn.inputs import net_input
from learn.numerics import flushing
from learn.train.checkpoint import versions
from learn.train.runs import ensure_model
from learn.train.validation import scores
from tactile.config import from_dict, read_toml
from tactile.dataset.boxes import BoxFolder
from tactile.dataset.reader import DatasetReader
from tactile.errors import ConfigError, DataError

DEFAULT_SIZE = (68, 100)  # (h, w) px: the paper's network input, also used for BoVW
TIMING = {
    "bovw": "image → label: descriptors, visual words, SVM",
    "vgg_svm": "image → label: VGG16 features (float, eval mode), SVM",
}


def load_classical(path: str | Path):
    """The model saved in ``path`` (``BagOfVisualWords`` or ``VggSvmClassifier``) with its
    ``meta`` dict attached; ``predict(images (S, h, w))`` -> (S,) class ids."""
    meta, arrays = load_npz(path)
    kind = BagOfVisualWords if meta["kind"] == "bovw" else VggSvmClassifier
    model = kind.from_arrays(meta, arrays)
    model.meta = meta
    return model


def split_images(
    data: str | Path,
    split: str,
    size: tuple[int, int],
    hand_classes=None,
    seed: int = 0,
    progress: bool = False,
):
    """(images (S, h, w) float32 in [0, 1], labels (S,) int64, class names) of ``split`` of a
    dataset or image folder, read as the networks read it (``learn.data.load.open_split``)."""
    ds = open_split(Path(data), split, "classify", tuple(size), hand_classes, seed)
    tensors = materialize(ds, split, progress)
    names = tuple(getattr(ds, "class_names", HAND_NAMES))
    return tensors.x[:, 0].numpy(), tensors.y.numpy().astype(np.int64), names


def confusion(labels: np.ndarray, pred: np.ndarray, n_classes: int) -> np.ndarray:
    """(C, C) int64 counts, rows true class, columns predicted."""
    flat = n_classes * np.asarray(labels, np.int64) + np.asarray(pred, np.int64)
    return np.bincount(flat, minlength=n_classes**2).reshape(n_classes, n_classes)


def make_model(
    arch: str, data, out: Path, table: Mapping, *, seed: int, init, epochs, progress: bool
):
    """An unfitted model and its input size (h, w) px. ``table``: config keys (BovwConfig /
    VggSvmConfig fields, and ``input_size`` for BoVW). vgg_svm: features of the VGG16 checkpoint
    ``init``, or of the vgg16 preset trained here into ``out/vgg16`` (``epochs``, ``seed``)."""
    table = dict(table)
    if "seed" in table:
        raise ConfigError("give the seed with --seed (seed=...), not in the config file")
    if arch == "bovw":
        size = tuple(table.pop("input_size", DEFAULT_SIZE))
        if len(size) != 2 or min(size) < 16:
            raise ConfigError(f"input_size {list(size)}: give [h, w] pixels, each >= 16")
        return BagOfVisualWords(from_dict(BovwConfig, {"seed": seed, **table})), size
    if "input_size" in table:
        raise ConfigError("input_size is set by the VGG16 checkpoint for vgg_svm; remove it")
    cfg = from_dict(VggSvmConfig, table)
    ckpt = (
        init
        if init is not None
        else ensure_model(
            "vgg16", data, out, epochs=epochs, seed=seed, progress=progress, name="vgg16"
        )
    )
    model = VggSvmClassifier.from_checkpoint(ckpt, cfg, seed=seed)
    return model, model.input_size


def train_classical(
    arch: str,
    data: str | Path,
    out: str | Path,
    *,
    seed: int = 0,
    hand_classes=None,
    init=None,
    epochs: int | None = None,
    config: Mapping | None = None,
    progress: bool = True,
) -> dict:
    """Fit ``arch`` (bovw | vgg_svm) on the train split, save ``out/model.npz`` and
    ``out/test_metrics.json``; returns the report dict (config, versions, seed, test scores)."""
    if arch not in CLASSICAL:
        raise ConfigError(f"unknown classical arch {arch!r}; choose one of: {', '.join(CLASSICAL)}")
    out = Path(out)
    model, size = make_model(
        arch, data, out, config or {}, seed=seed, init=init, epochs=epochs, progress=progress
    )
    x, y, names = split_images(data, "train", size, hand_classes, seed, progress)
    model.fit(x, y)
    desc = {
        "path": str(data),
        "hand_classes": None if hand_classes is None else list(hand_classes),
        "n_train": len(y),
    }
    cfg, arrays = model.to_arrays()
    meta = {
        "kind": arch,
        "config": cfg,
        "input_size": list(size),
        "class_names": list(names),
        "seed": seed,
        "versions": versions(),
        "data": desc,
    }  # vgg_svm: its VGG16's
    save_npz(out / MODEL_FILE, meta, arrays)
    x, y, _ = split_images(data, "test", size, hand_classes, seed, progress)
    cm = confusion(y, model.predict(x), len(names))
    report = {
        "config": cfg,
        "versions": meta["versions"],
        "seed": seed,
        "data": desc,
        "test_metrics": scores(cm),
        "test_confusion": cm.tolist(),
    }
    (out / "test_metrics.json").write_text(json.dumps(report, indent=1))
    return report


def train_checked(
    arch: str,
    data,
    out: Path,
    *,
    config_path: Path | None = None,
    seed: int | None = None,
    hand_classes=None,
    init: Path | None = None,
    epochs: int | None = None,
    unused: Mapping[str, object] | None = None,
    progress: bool = True,
) -> dict:
    """``handskin train --arch bovw|vgg_svm``: options checked (``unused``: option name → value
    of the network-only options, which must be None), then :func:`train_classical`."""
    given = [name for name, value in (unused or {}).items() if value is not None]
    if given:
        raise ConfigError(
            f"{given[0]} does not apply to --arch {arch} (no gradient training); remove it"
        )
    if arch == "bovw" and (init is not None or epochs is not None):
        raise ConfigError("--init and --epochs apply to --arch vgg_svm only; remove them")
    if init is not None and epochs is not None:
        raise ConfigError("--epochs trains a vgg16 when no --init is given; give one of the two")
    table = read_toml(config_path) if config_path is not None else {}
    return train_classical(
        arch,
        data,
        out,
        seed=seed or 0,
        hand_classes=hand_classes,
        init=init,
        epochs=epochs,
        config=table,
        progress=progress,
    )


def ms_per_image(
    model,
    images: np.ndarray,
    threads: int = 1,
    n_runs: int = 100,
    rounds: int = 3,
    n_warmup: int = 10,
) -> float:
    """CPU ms per image of ``model.predict`` at batch 1 (image k of ``images`` (S, h, w) at run
    k of a round, cycling) with ``threads`` torch threads: the least, over ``rounds`` rounds, of
    the median of ``n_runs`` runs after ``n_warmup`` warm-up runs — as networks are timed
    (`learn.infer.fastpath.interleaved_cpu_ms`; a classical model has one path, so its rounds follow
    each other). Raises ``ConfigError`` for fewer than one round, run or thread."""
    check_timing(n_runs, rounds, threads)
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    best = float("inf")
    try:
        for _ in range(rounds):
            times = []
            for k in range(n_warmup + n_runs):
                one = images[k % len(images)][None]
                start = time.perf_counter()
                model.predict(one)
                times.append(time.perf_counter() - start)
            best = min(best, float(np.median(times[n_warmup:])))
    finally:
        torch.set_num_threads(before)
    return 1e3 * best


def evaluate_classical(
    path: str | Path,
    data: str | Path,
    *,
    hand_classes=None,
    threads: int = 1,
    time_runs: int = 100,
    time_rounds: int = 3,
    progress: bool = True,
) -> dict:
    """Test-split scores and CPU ms/image of a classical model file; a row of
    ``learn.evaluate.report.write_report`` (the keys of ``evaluate_checkpoint``'s). Timed by
    :func:`ms_per_image` over ``time_rounds`` rounds of ``time_runs`` runs; ``progress``: a bar
    while the test images are read."""
    model = load_classical(path)
    meta = model.meta
    hand = hand_classes or meta["data"].get("hand_classes")
    x, y, names = split_images(data, "test", meta["input_size"], hand, meta["seed"], progress)
    if list(names) != list(meta["class_names"]):
        raise DataError(
            f"{data} has classes {list(names)}; {path} was trained on "
            f"{meta['class_names']}. Fix: the same kind of data (or --hand-classes)"
        )
    pred = model.predict(x)
    cm = confusion(y, pred, len(names))
    found = scores(cm)
    ms = ms_per_image(model, x, threads, time_runs, time_rounds)
    row = {
        "checkpoint": str(path),
        "arch": meta["kind"],
        "task": "classify",
        "epoch": None,
        "class_names": list(meta["class_names"]),
        "n_test": len(y),
        "cm": cm.tolist(),
        "metrics": found,
        "fast_metrics": found,
        "bf16": False,
        "ms_per_image": {"fast": ms, "gpu": None},
        "timing": TIMING[meta["kind"]],
        "threads": threads,
        "time_runs": time_runs,
        "time_rounds": time_rounds,
        "seed": meta["seed"],
        "config": meta["config"],
        "input_size": meta["input_size"],
        "train_versions": meta["versions"],
        "train_data": meta.get("data"),
        "test_data": str(data),
    }
    contacts = split_contacts(Path(data), "classify", meta["input_size"])
    if contacts is not None:  # by number of contacts (learn.evaluate.contacts)
        pred, y = torch.as_tensor(np.asarray(pred, np.int64)), torch.from_numpy(y)
        row |= contact_scores(pred, y, contacts, "classify", len(names))
    return row


@flushing()
def real_hand_scores(
    path: str | Path, folder: str | Path, negatives: str | Path | None = None
) -> dict:
    """A classical model file's row of `learn.evaluate.real.write_real_report`: its hand recall
    on the box folder ``folder`` (every print a hand) and its non-hand specificity on the test
    split of ``negatives`` (default: the dataset it was trained on), each image made into the
    model's input as in training."""
    model = load_classical(path)
    negatives = Path(negatives or trained_on(path, (model.meta.get("data") or {}).get("path")))
    names, size = list(model.meta["class_names"]), tuple(model.meta["input_size"])
    if "hand" not in names:
        raise ConfigError(f"{path}: its classes {names} have no 'hand'")
    hand = names.index("hand")
    prints = BoxFolder.open(folder)
    said = [int(model.predict(net_input(p.image, size, "classify")[None])[0]) for p in prints]
    k, n = sum(s == hand for s in said), len(said)
    with DatasetReader(negatives) as ds:
        test = split_non_hands(ds, negatives)
        right = 0
        for start in range(0, len(test), BATCH):
            x = net_input(ds.image[test[start : start + BATCH]], size, "classify")
            right += int((model.predict(x) != hand).sum())
    return {
        "checkpoint": str(path),
        "task": "classify",
        "folder": str(folder),
        "labels_from": "boxes",
        "hand_recall": k / n,
        "hand_recall_ci": wilson(k, n),
        "n_real": n,
        "negatives": str(negatives),
        "specificity": right / len(test),
        "specificity_ci": wilson(right, len(test)),
        "n_non_hand": len(test),
    }
