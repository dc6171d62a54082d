"""The configuration of learn/: which network, how it trains, how the data are used.

Frozen dataclasses, every field with its unit and the reason for its default. Values marked
*paper* are the paper's (Albini & Cannata, IJRR 2020, Tables 1 and 17); values marked *ours* are
choices argued here (the paper's Table 18 and its VGG16 settings were not available to us).

    run = load_run_config("docs/handsnet_paper.toml")      # a TOML file laid over RunConfig()
    run = replace_train(preset_run("segnet"), epochs=10)   # a preset with a change
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from tactile.config import from_dict, read_toml, to_dict
from tactile.errors import ConfigError

TASK_OF_ARCH = {
    "handsnet": "classify",
    "vgg16": "classify",
    "segnet": "segment",
    "fcn16s": "segment",
    "action_3d": "action",  # the action of a press from its sequence (learn.models.action)
    "compactseg": "segment",  # the compact segmenter (learn.models.compact)
    "handparts": "both",  # class and parts in one pass (learn.models.compact)
}
OPTIMIZERS = ("sgdm", "adam", "adamw")
LOSSES = ("ce", "weighted_ce", "dice", "generalized_dice", "ce_dice")
PRECISIONS = ("fp32", "bf16")
DEVICE_PATTERN = r"cpu|cuda(:\d+)?"

#: Options earlier handskin versions offered and dropped because they measured no gain
#: (docs/findings.md), with their "off" value: a checkpoint or TOML that sets one to anything
#: else is refused, one that holds the off value loads as if it were not there.
RETIRED = {
    "model": {"dropout_scale": 1.0},
    "train": {"ema_decay": 0.0, "label_smoothing": 0.0},
    "run": {
        "rot180": False,
        "shift_px": 0,
        "mixup_alpha": 0.0,
        "aux_types_weight": 0.0,
        "distill_from": "",
        "distill_weight": 0.5,
        "distill_temperature": 4.0,
    },
}


def _require(ok: bool, message: str) -> None:
    if not ok:
        raise ConfigError(message)


@dataclass(frozen=True)
class ModelConfig:
    """Which network to build (``learn.models.create_model``) and its size."""

    # handsnet, vgg16 (classifiers), segnet, fcn16s, compactseg (segmenters), handparts (class
    # and parts), action_3d (actions)
    arch: str = "handsnet"
    num_classes: int = 2  # 2 = hand / non-hand; 7 = background + 5 fingers + palm; 8 actions
    in_channels: int = 1  # tactile images are grey
    width: float | None = None  # channel multiplier (1.0 = VGG16's 64..512); None = model default
    input_size: tuple[int, int] = (68, 100)  # (h, w) px: the paper's resized tactile image
    # (H, W) mm of map the input covers, or None: each map is stretched to input_size (paper).
    # Given, every tactile image is centred on this canvas (zero-padded or cropped) before the
    # resize, so a millimetre is the same number of input pixels on any part: a model moved to
    # a smaller part sees prints at the size it was trained on (the forearm: 229 x 383 mm).
    canvas_mm: tuple[float, float] | None = None
    # HandsNet: the last layer starts at zero weights (*ours*): from Glorot init, Adam kills the
    # narrow ReLU head (64 -> 32 behind 60 % / 50 % dropout) within ~20 steps on sparse images.
    zero_init_output: bool = False

    def __post_init__(self) -> None:
        _require(
            self.arch in TASK_OF_ARCH,
            f"unknown arch {self.arch!r}; choose one of: {', '.join(TASK_OF_ARCH)}",
        )
        _require(self.num_classes >= 2, f"model.num_classes must be >= 2, not {self.num_classes}")
        _require(self.in_channels >= 1, "model.in_channels must be >= 1")
        _require(self.width is None or self.width > 0, "model.width must be > 0")
        _require(min(self.input_size) >= 1, "model.input_size must be positive pixels")
        _require(
            self.canvas_mm is None or min(self.canvas_mm) > 0,
            f"model.canvas_mm = {self.canvas_mm}: give (H, W) > 0 mm, e.g. [229, 383] (the "
            "forearm map), or leave it out to stretch each map",
        )

    def kwargs(self) -> dict[str, object]:
        """Keyword arguments of ``create_model(self.arch, **kwargs)``."""
        kw: dict[str, object] = {"num_classes": self.num_classes, "in_channels": self.in_channels}
        if self.arch == "handsnet":
            kw["input_size"] = self.input_size
            if self.zero_init_output:
                kw["zero_init_output"] = True
        elif self.width is not None:
            kw["width"] = self.width
        return kw


@dataclass(frozen=True)
class TrainConfig:
    """Optimisation of one run; the learning rate drops by a step schedule."""

    # SGD with momentum (the paper's), "adam" (weight decay as an L2 term in the gradient,
    # MATLAB's way) or "adamw" (decay decoupled from the gradient: then per unit lr, e.g. 0.05)
    optimizer: str = "sgdm"
    lr: float = 0.01  # initial learning rate (paper, Table 17)
    momentum: float = 0.9  # MATLAB sgdm's default (the paper names no value)
    weight_decay: float = 1e-4  # L2 factor: MATLAB's default L2Regularization
    lr_drop_factor: float = 0.2  # multiply the lr by this ... (paper, Table 17)
    lr_drop_period_epochs: int = 40  # ... every this many epochs (paper, Table 17)
    batch_size: int = 64  # images per step (paper, Table 17)
    epochs: int = 80  # passes over the training set (paper, Table 17)
    loss: str = "ce"  # one of LOSSES (learn.train.losses)
    # per-layer lr factors, selector -> factor (learn.train.optim.param_groups); 0 freezes
    lr_factors: Mapping[str, float] = field(default_factory=dict, hash=False)
    seed: int = 0  # torch / numpy seed of the run: init, shuffling, dropout, validation split

    def __post_init__(self) -> None:
        _require(
            self.optimizer in OPTIMIZERS,
            f"train.optimizer {self.optimizer!r}: choose one of {', '.join(OPTIMIZERS)}",
        )
        _require(
            self.loss in LOSSES, f"train.loss {self.loss!r}: choose one of {', '.join(LOSSES)}"
        )
        _require(self.lr > 0, f"train.lr (--lr) must be > 0, not {self.lr}")
        _require(self.weight_decay >= 0, "train.weight_decay must be >= 0")
        _require(0 < self.lr_drop_factor <= 1, "train.lr_drop_factor must be in (0, 1]")
        _require(self.lr_drop_period_epochs >= 1, "train.lr_drop_period_epochs must be >= 1")
        _require(
            self.batch_size >= 1,
            f"train.batch_size (--batch-size) must be >= 1, not {self.batch_size}",
        )
        _require(self.epochs >= 1, f"train.epochs (--epochs) must be >= 1, not {self.epochs}")
        _require(all(f >= 0 for f in self.lr_factors.values()), "train.lr_factors must be >= 0")


def _handsnet_default() -> ModelConfig:
    return HANDSNET.model


def _handsnet_train() -> TrainConfig:
    return HANDSNET.train


@dataclass(frozen=True)
class RunConfig:
    """A whole training run: model, optimisation, and how the data are used."""

    model: ModelConfig = field(default_factory=_handsnet_default)
    train: TrainConfig = field(default_factory=_handsnet_train)
    val_fraction: float = 0.15  # share of the train split's subjects / instances held out
    patience_epochs: int = 0  # stop after this many epochs without a better val metric; 0 = off
    # the paper's threefold augmentation: original, columns reversed, rows reversed. Flips also
    # mirror a hand: most simulated hands are right hands, and the flips teach the left ones.
    flips: bool = True
    threads: int = 2  # torch CPU threads
    # the training forward pass in "fp32", or "bf16" (bfloat16 autocast; weights, optimizer state,
    # loss and validation stay float32): ~1.8x faster steps on CPUs with AVX512-BF16 or AMX
    precision: str = "fp32"
    eval_batch_size: int = 64  # images per evaluation forward pass
    # "cpu" (bit-reproducible from the seed) or "cuda" / "cuda:N"; batches are drawn and
    # augmented on the CPU either way, so both see the same images
    device: str = "cpu"

    def __post_init__(self) -> None:
        _require(
            0.0 <= self.val_fraction < 1.0,
            f"val_fraction (--val-fraction) must be in [0, 1), not {self.val_fraction}",
        )
        _require(self.patience_epochs >= 0, "patience_epochs must be >= 0")
        _require(self.threads >= 1, f"threads must be >= 1, not {self.threads}")
        _require(self.eval_batch_size >= 1, "eval_batch_size must be >= 1")
        _require(
            re.fullmatch(DEVICE_PATTERN, self.device) is not None,
            f"device {self.device!r} (--device) is not a training device. Fix: cpu, cuda or cuda:N",
        )
        _require(
            self.precision in PRECISIONS,
            f"precision {self.precision!r} (--precision) is not a number format. Fix: fp32 or bf16",
        )
        _require(
            not (self.task not in ("segment", "both") and self.train.loss.endswith("dice")),
            f"train.loss {self.train.loss!r} is for segmentation; a classifier takes ce or "
            "weighted_ce",
        )

    @property
    def task(self) -> str:
        """``"classify"``, ``"segment"``, ``"both"`` or ``"action"``, from the architecture."""
        return TASK_OF_ARCH[self.model.arch]


@dataclass(frozen=True)
class BovwConfig:
    """Bag of visual words: SIFT descriptors -> k-means vocabulary -> histogram -> linear SVM."""

    vocabulary_size: int = 80  # visual words (paper)
    detector: str = "sift"  # sift (skimage keypoints, dense fallback per image) | dense
    grid_step_px: int = 4  # dense grid spacing, px: ~6 descriptors across a 28-px real image
    patch_px: int = 16  # dense descriptor support (4 x 4 cells of 4 px, as SIFT's)
    svm_c: float = 1.0  # LinearSVC C (*ours*: sklearn's default; the paper gives none)
    kmeans_batch_size: int = 1024  # MiniBatchKMeans batch (descriptors)
    seed: int = 0  # k-means and SVM seed

    def __post_init__(self) -> None:
        _require(self.vocabulary_size >= 2, "vocabulary_size must be >= 2")
        _require(self.detector in ("sift", "dense"), "detector: 'sift' or 'dense'")
        _require(self.grid_step_px >= 1, "grid_step_px must be >= 1")
        _require(self.patch_px >= 4 and self.patch_px % 4 == 0, "patch_px: a multiple of 4 px")
        _require(self.svm_c > 0, "svm_c must be > 0")


@dataclass(frozen=True)
class VggSvmConfig:
    """VGG16 features + linear SVM."""

    svm_c: float = 0.25  # LinearSVC C (paper)
    feature_layer: str = "fc7"  # fc7 (after ReLU) | pool5 (global-average-pooled conv features)
    standardize: bool = True  # zero-mean unit-variance features before the SVM (*ours*)
    batch_size: int = 64  # images per feature-extraction forward pass

    def __post_init__(self) -> None:
        _require(self.svm_c > 0, "svm_c must be > 0")
        _require(self.feature_layer in ("fc7", "pool5"), "feature_layer: fc7 or pool5")
        _require(self.batch_size >= 1, "batch_size must be >= 1")


#: HandsNet exactly as Table 17 of the paper (sgdm, lr 0.01, x 0.2 every 40 epochs, batch 64,
#: 80 epochs): about an hour for the paper-sized forearm set on 2 CPU cores.
HANDSNET_PAPER = RunConfig(ModelConfig("handsnet", 2), TrainConfig())

#: HandsNet on a CPU (*ours*): the paper's network and batch, Adam at lr 1e-3 (sgdm at 0.01 sat
#: at chance loss for its first epochs behind the head's dropout), 20 epochs with x 0.2 after 14,
#: the output layer started at zero (see ModelConfig.zero_init_output).
HANDSNET = RunConfig(
    ModelConfig("handsnet", 2, zero_init_output=True),
    TrainConfig(optimizer="adam", lr=0.001, lr_drop_period_epochs=14, epochs=20),
)

#: VGG16-style classifier trained end to end (*ours*): HandsNet's schedule at a tenth of its lr;
#: width 0.25 trains on a CPU (1.0 is VGG16's, for a GPU).
VGG16_FINETUNE = RunConfig(ModelConfig("vgg16", 2, width=0.25), TrainConfig(lr=0.001))

#: SegNet on a CPU (*ours*): median-frequency weighted CE (the paper's best loss for SegNet),
#: width 0.25 (1/16 of full-width VGG16's multiply-adds), Adam at 1e-3, batch 16, 30 epochs with
#: x 0.2 after 20. Segmenters see hand images only, as in the paper.
SEGNET = RunConfig(
    ModelConfig("segnet", 7, width=0.25),
    TrainConfig(
        optimizer="adam",
        lr=0.001,
        lr_drop_period_epochs=20,
        batch_size=16,
        epochs=30,
        loss="weighted_ce",
    ),
)

#: SegNet at full width for a GPU (*ours*): sgdm lr 0.01, 60 epochs, x 0.2 every 30.
SEGNET_GPU = RunConfig(
    ModelConfig("segnet", 7, width=1.0),
    TrainConfig(lr=0.01, lr_drop_period_epochs=30, batch_size=16, epochs=60, loss="weighted_ce"),
)

#: FCN-16s (*ours*): SegNet's CPU schedule, width and loss, so the two compare. The paper found
#: Dice best for FCN; here Dice sat at background-only for its first epochs (docs/findings.md).
FCN16S = dataclasses.replace(SEGNET, model=ModelConfig("fcn16s", 7, width=0.25))

#: The action network (*ours*): 8 actions, frames at 34 x 50 px (HandsNet's pareto point),
#: Adam at 1e-3, batch 32 sequences, 30 epochs with x 0.2 after 20 (its scores: README, "The
#: action from its 10 Hz sequence").
ACTION_3D = RunConfig(
    ModelConfig("action_3d", 8, input_size=(34, 50)),
    TrainConfig(optimizer="adam", lr=0.001, lr_drop_period_epochs=20, batch_size=32, epochs=30),
    eval_batch_size=32,
)

#: The compact segmenter (*ours*): SegNet's CPU recipe (Adam, weighted CE, batch 16, 30 epochs,
#: lr x 0.2 after 20), the encoder-decoder of `learn.models.compact` at width 1.
COMPACTSEG = dataclasses.replace(SEGNET, model=ModelConfig("compactseg", 7, width=1.0))

#: Class and parts in one pass (*ours*): the compact segmenter with a hand / non-hand head,
#: trained on every image (parts on the hands', `learn.train.losses.BothLoss`), same recipe, at
#: width 2: the fastest network within 3 points of the best part localisation on real prints
#: (reports/candidates: width 1 lies 8 points below, width 2 2.8 points, at 1.5 ms a full answer).
HANDPARTS = dataclasses.replace(SEGNET, model=ModelConfig("handparts", 7, width=2.0))

#: the preset of each network (``handskin train --arch``'s default configuration)
PRESET_OF_ARCH = {
    "handsnet": HANDSNET,
    "vgg16": VGG16_FINETUNE,
    "segnet": SEGNET,
    "fcn16s": FCN16S,
    "action_3d": ACTION_3D,
    "compactseg": COMPACTSEG,
    "handparts": HANDPARTS,
}

#: Fine-tuning of the paper's Test C: lr x 0.1 on the first two convolutions, lr 0.01 halved
#: after 60 of 120 epochs, batch 128 (paper).
FINETUNE_TEST_C = TrainConfig(
    lr=0.01,
    lr_drop_factor=0.5,
    lr_drop_period_epochs=60,
    batch_size=128,
    epochs=120,
    lr_factors={"first_two_convs": 0.1},
)


def metric_name(task: str) -> str:
    """The validation metric that selects the best epoch: accuracy or mean IoU."""
    return {"segment": "mean_iou", "both": "class_and_parts"}.get(task, "accuracy")


def replace_train(run: RunConfig, **changes: object) -> RunConfig:
    """A copy of ``run`` with TrainConfig fields changed (validated)."""
    return dataclasses.replace(run, train=dataclasses.replace(run.train, **changes))


def preset_run(arch: str, *, device: str = "cpu", **train_changes: object) -> RunConfig:
    """The preset of ``arch`` training on ``device``, with the TrainConfig fields that are not
    None changed."""
    if arch not in PRESET_OF_ARCH:
        raise ConfigError(f"unknown arch {arch!r}; choose one of: {', '.join(PRESET_OF_ARCH)}")
    run = dataclasses.replace(PRESET_OF_ARCH[arch], device=device)
    changes = {k: v for k, v in train_changes.items() if v is not None}
    return replace_train(run, **changes) if changes else run


def _drop_retired(table: dict, where: str) -> dict:
    """``table`` (a RunConfig dict) without retired keys at their off value; ConfigError naming
    ``where`` when one is set to anything else."""
    out = dict(table)
    for part, keys in RETIRED.items():
        node = out if part == "run" else dict(out.get(part) or {})
        for key, off in keys.items():
            if key in node and node.pop(key) != off:
                raise ConfigError(
                    f"{where} sets {key}, an option handskin no longer has (it measured no "
                    "gain: docs/findings.md). Fix: remove it, or retrain without it"
                )
        if part != "run" and part in out:
            out[part] = node
    return out


def _merge(base: dict, table: Mapping) -> dict:
    """``base`` with ``table``'s keys laid over it, recursively for sub-tables."""
    out = dict(base)
    for key, value in table.items():
        nested = isinstance(value, Mapping) and isinstance(base.get(key), dict)
        out[key] = _merge(base[key], value) if nested and key != "lr_factors" else value
    return out


def run_from_dict(
    table: Mapping, base: RunConfig | None = None, where: str = "the configuration"
) -> RunConfig:
    """RunConfig from a nested dict (tables ``model``, ``train`` and top-level keys, as TOML and
    checkpoints hold them) laid over ``base`` (default RunConfig()); unknown keys and bad values
    raise ConfigError. A key added after a checkpoint was written takes its default."""
    table = _merge(to_dict(base or RunConfig()), _drop_retired(dict(table), where))
    train = dict(table.get("train") or {})
    factors = train.pop("lr_factors", {}) or {}
    if not isinstance(factors, Mapping) or not all(
        isinstance(v, int | float) and not isinstance(v, bool) for v in factors.values()
    ):
        raise ConfigError(f"train.lr_factors: expected a table selector = factor, got {factors!r}")
    run = from_dict(RunConfig, {**table, "train": train})
    return replace_train(run, lr_factors={str(k): float(v) for k, v in factors.items()})


def load_run_config(path: str | Path, base: RunConfig | None = None) -> RunConfig:
    """A TOML run configuration laid over ``base``; ConfigError names the file and the key."""
    try:
        return run_from_dict(read_toml(path), base, str(path))
    except ConfigError as err:
        if str(err).startswith(str(path)):
            raise
        raise ConfigError(f"{path}: {err}") from err
