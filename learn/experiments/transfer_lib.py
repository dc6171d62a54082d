"""Test C, the learning half of `handskin experiment transfer` (datasets come from handskin/).

    s = TransferSettings(finetune_epochs=120)
    res = run_transfer("data/forearm", "data/ee", "data/ee_synthetic", "out", s)

For each task (classification unless turned off, and segmentation when asked or a segmenter
is given):
1. the forearm model (given, or trained on ``source``) scores the end-effector test split as it is
   (zero-shot, the paper's Table 15); images of any map size are resized to the model's input;
2. it is fine-tuned with the paper's Test C recipe on the end-effector train split (Table 16);
3. the generator's own answer: a model trained on a *synthetic* end-effector set (another seed;
   its samples whose object / body-part instance is in the target's test split left out);
4. the learning curve: fine-tuning on N = ``curve_sizes`` and all end-effector train samples
   (nested, class-balanced prefixes of the train split, so subject- and instance-disjoint from
   test) from scratch, from the forearm model and from the synthetic end-effector model;
5. with ``keep_scale``, steps 1, 2 and 4 again for the forearm model at its own scale
   ("forearm at scale"): each end-effector image centred on a canvas of the forearm map's size
   in mm (``ModelConfig.canvas_mm``) instead of stretched to the input, so that a hand's print
   covers as many input pixels as on the forearm.

Every fine-tuning result is kept under ``<models>/finetune/`` with its key
(`learn.experiments.transfer_cache`), so a stopped run resumes at the next one.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from tactile.errors import ConfigError
from tactile.resize import NET_SIZE

ARCH = {"classify": "handsnet", "segment": "segnet"}
INITS = ("scratch", "forearm", "synthetic EE")
AT_SCALE = "forearm at scale"  # the forearm model on a canvas of its map (keep_scale)


@dataclass(frozen=True)
class TransferSettings:
    """What the learning half runs; every random draw comes from ``seed``."""

    curve_sizes: tuple[int, ...] = (10, 30, 100, 300)  # EE train samples per point ("all" added)
    finetune_epochs: int = 120  # Test C recipe (paper: 120, lr halved after half of them)
    pretrain_epochs: int = 80  # models trained here from scratch (HandsNet preset: 80)
    pretrain_flips: bool = True  # the paper's threefold flips while pretraining (False: faster)
    input_size: tuple[int, int] = NET_SIZE  # (h, w) px of models trained here
    segmentation: bool = False  # also SegNet (zero-shot, fine-tune, curve)
    classification: bool = True  # HandsNet (zero-shot, fine-tune, curve); False: SegNet alone
    seed: int = 0
    threads: int = 2  # torch CPU threads
    precision: str = "fp32"  # training forward pass of every run here ("bf16": RunConfig.precision)
    keep_scale: bool = False  # also the forearm model at its own mm per pixel (AT_SCALE rows)
    device: str = "cpu"  # where every run here trains (RunConfig.device: "cpu", "cuda", "cuda:N")

    def __post_init__(self) -> None:
        if not self.curve_sizes or min(self.curve_sizes) < 1:
            raise ConfigError(f"curve sizes must be >= 1 samples, got {self.curve_sizes}")
        if min(self.finetune_epochs, self.pretrain_epochs, self.threads) < 1:
            raise ConfigError("finetune_epochs, pretrain_epochs and threads must be >= 1")
        if not (self.classification or self.segmentation):
            raise ConfigError(
                "neither classification nor segmentation is asked for. Fix: drop "
                "--no-classification or add --segmentation"
            )
        if (self.precision, self.device) != ("fp32", "cpu"):  # unknown, or absent (imports torch)
            from learn.train import RunConfig, check_precision

            check_precision(RunConfig(precision=self.precision, device=self.device))


def nested_order(labels: np.ndarray, seed: int) -> np.ndarray:
    """(S,) positions whose every prefix holds each class in proportion (±1 sample).

    labels : (S,) int class of each sample. Each class is shuffled (seeded); item k of class c
    gets the key (k + 0.5) / n_c and the items are merged by key, so the first N positions are a
    class-balanced random subset and the subsets of growing N are nested.
    """
    rng = np.random.default_rng(seed)
    labels = np.asarray(labels)
    pos, keys = [], []
    for c in np.unique(labels):
        members = rng.permutation(np.flatnonzero(labels == c))
        pos.append(members)
        keys.append((np.arange(len(members)) + 0.5) / len(members))
    pos, keys = np.concatenate(pos), np.concatenate(keys)
    return pos[np.argsort(keys, kind="stable")]


def model_config(task: str, checkpoint: Path | None, s: TransferSettings):
    """The ModelConfig of the task: the given checkpoint's, or the preset's at ``input_size``."""
    from learn.checkpoint import load_checkpoint
    from learn.experiments.models import preset_run
    from learn.train import run_from_dict

    if checkpoint is not None:
        model = run_from_dict(load_checkpoint(checkpoint)["config"]).model
        if (model.arch in ("handsnet", "vgg16")) != (task == "classify"):
            raise ConfigError(
                f"{checkpoint} is a {model.arch} checkpoint, not a "
                f"{'classifier' if task == 'classify' else 'segmenter'}"
            )
        if s.keep_scale and model.canvas_mm is not None:
            raise ConfigError(
                f"{checkpoint} already centres its inputs on a {model.canvas_mm} "
                "mm canvas, so its 'forearm' rows keep its scale. Fix: drop "
                "--keep-scale"
            )
        return model
    return dataclasses.replace(preset_run(ARCH[task]).model, input_size=s.input_size)


def map_mm(path: Path) -> tuple[float, float]:
    """(H, W) mm of the tactile map of the dataset at ``path``."""
    from tactile.dataset.reader import DatasetReader

    with DatasetReader(path) as ds:
        shape, step = ds.map.shape, ds.map.step_mm
    return (shape[0] * step, shape[1] * step)


def drop_epoch(epochs: int) -> int:
    """Epoch after which Test C halves the lr: half the epochs (paper: 60 of 120), at least 1."""
    return max(1, epochs // 2)


def finetune_run(model, s: TransferSettings, scratch: bool):
    """The Test C recipe (lr 0.01 halved at half the epochs, batch 128, lr × 0.1 on the first two
    convolutions; from scratch without that factor), no validation, the preset's loss."""
    from learn import config as C
    from learn.experiments.models import preset_run
    from learn.train import RunConfig

    train = dataclasses.replace(
        C.FINETUNE_TEST_C,
        epochs=s.finetune_epochs,
        seed=s.seed,
        lr_drop_period_epochs=drop_epoch(s.finetune_epochs),
        loss=preset_run(model.arch).train.loss,
        lr_factors={} if scratch else C.FINETUNE_TEST_C.lr_factors,
    )
    return RunConfig(
        model=model,
        train=train,
        val_fraction=0.0,
        threads=s.threads,
        precision=s.precision,
        device=s.device,
    )


def pretrain_run(model, s: TransferSettings):
    """The arch's preset at ``model`` (size, width) with ``pretrain_epochs`` and the seed."""
    from learn.experiments.models import preset_run

    run = preset_run(model.arch, epochs=s.pretrain_epochs, seed=s.seed)
    return dataclasses.replace(
        run,
        model=model,
        flips=s.pretrain_flips,
        threads=s.threads,
        precision=s.precision,
        device=s.device,
    )


def held_out_instances(target: Path) -> np.ndarray:
    """(K,) object / body-part instance ids (>= 0) of the target's test split."""
    from tactile.dataset.reader import DatasetReader

    with DatasetReader(target) as ds:
        if "instance_id" not in ds.fields:
            return np.zeros(0, np.int64)
        ids = ds["instance_id"][:][ds.splits["test"]]
    return np.unique(ids[ids >= 0]).astype(np.int64)


def pretrain_data(pretrain: Path, target: Path, run, progress: bool):
    """Data of the synthetic set: all its samples except those whose instance is in the
    target's test split, minus a subject-disjoint validation part; no test split."""
    from learn.data import TorchTactileDataset
    from learn.folder import Data, _class_names, materialize, subset, validation_split
    from tactile.dataset.reader import DatasetReader

    ds = TorchTactileDataset(pretrain, None, run.task, run.model.input_size, flips=False)
    with DatasetReader(pretrain) as r:
        inst = r["instance_id"][:] if "instance_id" in r.fields else np.full(len(r), -1)
    # positions in ds.indices (for segmentation, the hand samples only), not dataset rows
    keep = np.flatnonzero(~np.isin(inst[np.asarray(ds.indices)], held_out_instances(target)))
    train, val = validation_split(subset(ds, keep), run.val_fraction, run.train.seed)
    desc = {
        "path": str(pretrain),
        "kind": "dataset",
        "n_train": len(train.indices),
        "n_val": 0 if val is None else len(val.indices),
        "n_test": 0,
        "n_dropped_shared_instances": len(ds.indices) - len(keep),
    }
    return Data(
        materialize(train, "pretrain", progress),
        None if val is None else materialize(val, "pretrain val", progress),
        None,
        _class_names(train, run.task),
        desc,
    )


def synthetic_model(
    pretrain: Path, target: Path, model, models_dir: Path, s: TransferSettings, progress: bool
) -> Path:
    """Checkpoint of the model trained on the synthetic end-effector set (reused when finished,
    resumed when stopped)."""
    from learn.experiments.models import train_once

    out, run = models_dir / f"ee-synthetic-{model.arch}", pretrain_run(model, s)
    return train_once(
        out, run, lambda: pretrain_data(pretrain, target, run, progress), progress=progress
    )[0]


def score(model_or_ckpt, test, num_classes: int) -> dict:
    """Metrics (fractions) and confusion matrix (rows true) of a model or checkpoint on test."""
    from learn.checkpoint import load_checkpoint, model_from_checkpoint
    from learn.evaluate import evaluate_tensors

    model = model_or_ckpt
    if isinstance(model_or_ckpt, str | Path):
        model = model_from_checkpoint(load_checkpoint(model_or_ckpt))[0]
    res = evaluate_tensors(model, test, num_classes)
    return {"metrics": res.metrics, "cm": res.cm.tolist()}


def target_data(target: Path, run, progress: bool):
    """(Data of the target: its train rows in split order (for segmentation, the hand ones only,
    as ``load_data`` keeps), test; (S,) is_hand and (S,) dataset sample index of those rows)."""
    from learn.folder import load_data
    from tactile.dataset.reader import DatasetReader

    data = load_data(target, run, progress=progress)
    with DatasetReader(target) as ds:
        index = ds.splits["train"]
        hand = ds["is_hand"][:][index]
    if run.task == "segment":
        index, hand = index[hand == 1], hand[hand == 1]
    if len(index) != len(data.train.y):
        raise AssertionError(f"{len(index)} train rows of {target} but {len(data.train.y)} loaded")
    return data, hand, index


def finetune(
    run,
    data,
    rows: np.ndarray,
    index: np.ndarray,
    init: Path | None,
    progress: bool,
    cache: tuple[Path, Path] | None = None,
) -> dict:
    """Fine-tune on the train rows ``rows`` and score on data.test; ``samples``: the dataset
    indices trained on (``index[rows]``, sorted). ``cache`` = (result file, target dataset):
    the result is read from the file when it was computed for the same run, start, target and
    samples, else computed and written there (`learn.experiments.transfer_cache`)."""
    from learn.experiments.transfer_cache import cached, finetune_key
    from learn.folder import Data, TensorData
    from learn.train import fit

    samples = np.sort(index[rows]).tolist()

    def compute() -> dict:
        sub = Data(
            TensorData(data.train.x[rows], data.train.y[rows]),
            None,
            data.test,
            data.class_names,
            data.description,
        )
        result = fit(run, sub, None, init_from=init, progress=progress)
        return score(result.model, data.test, run.model.num_classes) | {
            "n": len(rows),
            "samples": samples,
        }

    if cache is None:
        return compute()
    return cached(cache[0], finetune_key(run, init, cache[1], samples), compute)


def transfer_task(
    task: str,
    source: Path,
    target: Path,
    pretrain: Path,
    models_dir: Path,
    s: TransferSettings,
    checkpoint: Path | None,
    progress: bool,
) -> dict:
    """Zero-shot, Test C fine-tuning and the learning curve of one task (see module doc)."""
    from learn.experiments.models import ensure_model

    model = model_config(task, checkpoint, s)
    forearm = ensure_model(
        model.arch,
        source,
        models_dir,
        checkpoint=checkpoint,
        run=pretrain_run(model, s),
        name=f"forearm-{model.arch}",
        progress=progress,
    )
    synthetic = synthetic_model(pretrain, target, model, models_dir, s, progress)
    run = finetune_run(model, s, scratch=False)
    data, hand, index = target_data(target, run, progress)
    n_cls, order = model.num_classes, nested_order(hand, s.seed)
    out = {
        "model": dataclasses.asdict(model),
        "forearm_checkpoint": str(forearm),
        "synthetic_checkpoint": str(synthetic),
        "n_train": len(hand),
        "n_test": len(data.test.y),
        "class_names": list(data.class_names),
        "zero_shot": {
            "forearm": score(forearm, data.test, n_cls),
            "synthetic EE": score(synthetic, data.test, n_cls),
        },
    }
    sizes = sorted({n for n in s.curve_sizes if n < len(hand)} | {len(hand)})
    inits = {"scratch": None, "forearm": forearm, "synthetic EE": synthetic}

    def cache(name: str, n: int) -> tuple[Path, Path]:
        return models_dir / "finetune" / f"{task}-{name.replace(' ', '_')}-{n}.json", target

    out["finetuned"] = finetune(
        run, data, order, index, forearm, progress, cache("forearm", len(hand))
    )
    starts, scaled = {name: (inits[name], data) for name in INITS}, model
    if s.keep_scale:  # the same forearm weights, fed the target's images at the forearm's scale
        scaled = dataclasses.replace(model, canvas_mm=map_mm(source))
        data_s = target_data(target, finetune_run(scaled, s, scratch=False), progress)[0]
        out["zero_shot"][AT_SCALE] = score(forearm, data_s.test, n_cls)
        out["canvas_mm"] = list(scaled.canvas_mm)
        starts[AT_SCALE] = (forearm, data_s)
    out["curve"] = {name: [] for name in starts}
    for name, (init, d) in starts.items():
        m = scaled if name == AT_SCALE else model
        for n in sizes:
            if name == "forearm" and n == len(hand):
                out["curve"][name].append(out["finetuned"])
                continue
            ft = finetune_run(m, s, scratch=name == "scratch")
            out["curve"][name].append(
                finetune(ft, d, order[:n], index, init, progress, cache(name, n))
            )
    return out
