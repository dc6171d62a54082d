"""Test C, the learning part of `handskin experiment transfer` (``experiments.transfer``).

For each task (classification unless turned off, segmentation when asked or a segmenter is
given), ``transfer_task``:
1. scores the source model (given, or trained on the source dataset) on the target's test
   split as it is (zero-shot, the paper's Table 15); images of any map size are resized to the
   model's input;
2. fine-tunes it with the paper's Test C recipe on the target's train split (Table 16);
3. trains the generator's own answer: a model of a *synthetic* target set (another seed; its
   samples whose object or body-part instance is in the target's test split left out);
4. draws the learning curve: fine-tuning on N = ``curve_sizes`` and all target train samples
   (nested, class-balanced prefixes of the train split, so subject- and instance-disjoint from
   the test split) from scratch, from the source model and from the synthetic model;
5. with ``keep_scale``, steps 1, 2 and 4 again for the source model at its own scale ("forearm
   at scale"): each target image centred on a canvas of the source map's size in mm
   (``ModelConfig.canvas_mm``) instead of stretched to the input.

Every fine-tuning result is kept in ``<models>/finetune/<task>-<start>-<n>.json`` with the key
it was computed for (the run configuration, the start checkpoint's sha256, the target dataset's
fingerprint, the train samples), so a stopped run resumes at the next one.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from learn import config as C
from learn.data.dataset import TorchTactileDataset
from learn.data.folder import HAND_NAMES
from learn.data.load import Data, TensorData, load_data, materialize, subset, validation_split
from learn.train.checkpoint import load_checkpoint, model_from_checkpoint, run_of
from learn.train.loop import fit
from learn.train.runs import ensure_model, train_once
from learn.train.validation import evaluate_tensors
from tactile.config import to_dict
from tactile.dataset.reader import DatasetReader
from tactile.errors import ConfigError
from tactile.images.labels import CLASS_NAMES

ARCH = {"classify": "handsnet", "segment": "segnet"}
AT_SCALE = "forearm at scale"  # the source model on a canvas of its map (keep_scale)


def nested_order(labels: np.ndarray, seed: int) -> np.ndarray:
    """(S,) positions whose every prefix holds each class in proportion (±1 sample).

    labels : (S,) int class of each sample. Each class is shuffled (seeded); item k of class c
    gets the key (k + 0.5) / n_c and the items are merged by key, so the first N positions are a
    class-balanced random subset and the subsets of growing N are nested.
    """
    rng, labels = np.random.default_rng(seed), np.asarray(labels)
    members = [rng.permutation(np.flatnonzero(labels == c)) for c in np.unique(labels)]
    keys = np.concatenate([(np.arange(len(m)) + 0.5) / len(m) for m in members])
    return np.concatenate(members)[np.argsort(keys, kind="stable")]


def model_config(task: str, checkpoint: Path | None, s):
    """The ModelConfig of the task: the given checkpoint's, or the preset's at ``input_size``."""
    if checkpoint is None:
        return dataclasses.replace(C.preset_run(ARCH[task]).model, input_size=s.input_size)
    model = run_of(load_checkpoint(checkpoint), checkpoint).model
    flag = "--classifier" if task == "classify" else "--segmenter"
    if C.TASK_OF_ARCH[model.arch] != task:
        archs = ", ".join(a for a, t in C.TASK_OF_ARCH.items() if t == task)
        raise ConfigError(f"{flag} {checkpoint} holds a {model.arch} network; give one of {archs}")
    if s.keep_scale and model.canvas_mm is not None:
        raise ConfigError(
            f"{flag} {checkpoint} already centres its inputs on a {model.canvas_mm} mm canvas, "
            "so its 'forearm' rows keep its scale. Fix: drop --keep-scale"
        )
    return model


def map_mm(path: Path) -> tuple[float, float]:
    """(H, W) mm of the tactile map of the dataset at ``path``."""
    with DatasetReader(path) as ds:
        shape, step = ds.map.shape, ds.map.step_mm
    return (shape[0] * step, shape[1] * step)


def finetune_run(model, s, scratch: bool):
    """The Test C recipe (lr 0.01 halved at half the epochs, batch 128, lr × 0.1 on the first two
    convolutions; from scratch without that factor), no validation, the preset's loss."""
    train = dataclasses.replace(
        C.FINETUNE_TEST_C,
        epochs=s.finetune_epochs,
        seed=s.seed,
        lr_drop_period_epochs=s.halved_after,
        loss=C.preset_run(model.arch).train.loss,
        lr_factors={} if scratch else C.FINETUNE_TEST_C.lr_factors,
    )
    where = {"threads": s.threads, "precision": s.precision, "device": s.device}
    return C.RunConfig(model=model, train=train, val_fraction=0.0, **where)


def pretrain_run(model, s):
    """The arch's preset at ``model`` (size, width) with ``pretrain_epochs`` and the seed."""
    run = C.preset_run(model.arch, epochs=s.pretrain_epochs, seed=s.seed)
    where = {"threads": s.threads, "precision": s.precision, "device": s.device}
    return dataclasses.replace(run, model=model, flips=s.pretrain_flips, **where)


def pretrain_data(pretrain: Path, target: Path, run, progress: bool) -> Data:
    """Data of the synthetic set: all its samples except those whose instance is in the
    target's test split, minus a subject-disjoint validation part; no test split."""
    ds = TorchTactileDataset(pretrain, None, run.task, run.model.input_size, flips=False)
    with DatasetReader(target) as r:
        has = "instance_id" in r.fields
        held = r["instance_id"][:][r.splits["test"]] if has else np.zeros(0, np.int64)
    with DatasetReader(pretrain) as r:
        inst = r["instance_id"][:] if "instance_id" in r.fields else np.full(len(r), -1)
    # positions in ds.indices (for segmentation, the hand samples only), not dataset rows
    keep = np.flatnonzero(~np.isin(inst[np.asarray(ds.indices)], held[held >= 0]))
    train, val = validation_split(subset(ds, keep), run.val_fraction, run.train.seed)
    desc = {"path": str(pretrain), "kind": "dataset", "n_train": len(train.indices)}
    desc |= {"n_val": 0 if val is None else len(val.indices), "n_test": 0}
    desc |= {"n_dropped_shared_instances": len(ds.indices) - len(keep)}
    names = HAND_NAMES if run.task == "classify" else CLASS_NAMES
    x_val = None if val is None else materialize(val, "pretrain val", progress)
    return Data(materialize(train, "pretrain", progress), x_val, None, names, desc)


def score(model_or_ckpt, test: TensorData, num_classes: int) -> dict:
    """Metrics (fractions) and confusion matrix (rows true) of a model or checkpoint on test."""
    model = model_or_ckpt
    if isinstance(model, str | Path):
        model = model_from_checkpoint(load_checkpoint(model), where=model)[0]
    res = evaluate_tensors(model, test, num_classes)
    return {"metrics": res.metrics, "cm": res.cm.tolist()}


def target_data(target: Path, run, progress: bool):
    """(Data of the target: its train rows in split order (for segmentation, the hand ones only,
    as ``load_data`` keeps), test; (S,) is_hand and (S,) dataset sample index of those rows)."""
    data = load_data(target, run, progress=progress)
    with DatasetReader(target) as ds:
        index = ds.splits["train"]
        hand = ds["is_hand"][:][index]
    if run.task == "segment":
        index, hand = index[hand == 1], hand[hand == 1]
    return data, hand, index


def cached(path: Path, key: dict, compute: Callable[[], dict]) -> dict:
    """The result stored at ``path`` for ``key``, or ``compute()`` written there first
    (atomically: a killed run leaves no torn file)."""
    key = json.loads(json.dumps(key))  # as it reads back from the file (tuples as lists)
    try:
        stored = json.loads(path.read_text(encoding="utf-8")) if path.is_file() else {}
    except ValueError:
        stored = {}
    if stored.get("key") == key:
        print(f"reusing {path}")
        return stored["result"]
    result = compute()
    path.parent.mkdir(parents=True, exist_ok=True)
    path.with_suffix(".json.tmp").write_text(json.dumps({"key": key, "result": result}))
    os.replace(path.with_suffix(".json.tmp"), path)
    return result


def finetune(run, data: Data, rows, index, init: Path | None, progress: bool, cache: Path) -> dict:
    """Fine-tune on the train rows ``rows`` (positions in data.train; ``index``: their dataset
    samples) from ``init`` (None: from scratch) and score on data.test; the result is read
    from the file ``cache`` when it was computed for the same run, start, target and samples."""
    samples = np.sort(index[rows]).tolist()
    with DatasetReader(data.description["path"]) as ds:
        target = {"fingerprint": ds.attrs.get("fingerprint"), "n": len(ds)}
    start = None
    if init is not None:
        with open(init, "rb") as f:
            start = hashlib.file_digest(f, "sha256").hexdigest()
    sha = hashlib.sha256(json.dumps(samples).encode()).hexdigest()
    key = {"config": to_dict(run), "init": start, "target": target, "samples": sha}

    def compute() -> dict:
        train = TensorData(data.train.x[rows], data.train.y[rows])
        model = fit(run, dataclasses.replace(data, train=train), None, init=init, progress=progress)
        res = score(model.model, data.test, run.model.num_classes)
        return res | {"n": len(rows), "samples": samples}

    return cached(cache, key, compute)


def transfer_task(task, source, target, pretrain, models_dir: Path, s, checkpoint, progress):
    """Zero-shot, Test C fine-tuning and the learning curve of one task (see the module doc)."""
    model = model_config(task, checkpoint, s)
    run, name = pretrain_run(model, s), f"forearm-{model.arch}"
    kw = {"checkpoint": checkpoint, "run": run, "name": name, "progress": progress}
    forearm = ensure_model(model.arch, source, models_dir, **kw)
    make = functools.partial(pretrain_data, pretrain, target, run, progress)
    synthetic, _ = train_once(
        models_dir / f"ee-synthetic-{model.arch}", run, make, progress=progress
    )
    data, hand, index = target_data(target, finetune_run(model, s, scratch=False), progress)
    starts = {"scratch": (None, data, model), "forearm": (forearm, data, model)}
    starts["synthetic EE"] = (synthetic, data, model)
    out = {"model": dataclasses.asdict(model), "n_train": len(hand), "n_test": len(data.test.y)}
    if s.keep_scale:  # the same source weights, fed the target's images at the source's scale
        scaled = dataclasses.replace(model, canvas_mm=map_mm(source))
        data_s = target_data(target, finetune_run(scaled, s, scratch=False), progress)[0]
        out["canvas_mm"], starts[AT_SCALE] = list(scaled.canvas_mm), (forearm, data_s, scaled)
    out["zero_shot"] = {
        k: score(init, d.test, model.num_classes) for k, (init, d, _) in starts.items() if init
    }
    out |= {"forearm_checkpoint": str(forearm), "synthetic_checkpoint": str(synthetic)}
    out |= {"class_names": list(data.class_names), "curve": {k: [] for k in starts}}
    sizes, order = (
        sorted({n for n in s.curve_sizes if n < len(hand)} | {len(hand)}),
        nested_order(hand, s.seed),
    )
    for name, (init, d, m) in starts.items():
        ft = finetune_run(m, s, scratch=init is None)
        for n in sizes:
            cache = models_dir / "finetune" / f"{task}-{name.replace(' ', '_')}-{n}.json"
            out["curve"][name].append(finetune(ft, d, order[:n], index, init, progress, cache))
    out["finetuned"] = out["curve"]["forearm"][-1]
    return out
