"""A training run's configuration: model, optimisation and how the data are used.

    run = load_run_config("docs/handsnet_paper.toml")     # TOML laid over RunConfig()
    run = replace_train(run, epochs=20, seed=1)

``run_from_dict`` reads the nested tables a checkpoint stores (``config``), so a checkpoint
written before a key existed loads with that key's default.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from learn.config import HANDSNET, ModelConfig, TrainConfig
from tactile.config import from_dict, read_toml, to_dict
from tactile.errors import ConfigError

PRECISIONS = ("fp32", "bf16")  # RunConfig.precision: the training forward pass's number format
DEVICE_PATTERN = r"cpu|cuda(:\d+)?"  # RunConfig.device: the CPU, or a CUDA GPU (by index)
TASK_OF_ARCH = {
    "handsnet": "classify",
    "vgg16": "classify",
    "segnet": "segment",
    "fcn16s": "segment",
}


@dataclass(frozen=True)
class RunConfig:
    """A whole training run: model, optimisation, and how the data are used."""

    model: ModelConfig = field(default_factory=lambda: HANDSNET.model)
    train: TrainConfig = field(default_factory=lambda: HANDSNET.train)
    val_fraction: float = 0.15  # share of the train split's subjects/instances held out
    patience_epochs: int = 0  # early stopping after this many epochs without a better val metric
    # the paper's threefold augmentation (False: originals only). Measured on the paper-sized
    # forearm set at equal steps, without flips: HandsNet 88.97 % (91.83 % with), SegNet mIoU
    # 52.0 % (53.5 %): right hands 55.0 % (52.8 %), left hands 37.4 % (58.1 %). Most hands are
    # right hands; the flips are how a segmenter learns the left ones.
    flips: bool = True
    # one more view, both flips: a 180-degree turn. A single flip mirrors a print, so a right
    # hand looks like a left one with the same part labels; the turn keeps its chirality.
    # SegNet with it, same steps: 52.8 % mIoU (53.5 % without), so it is off by default.
    rot180: bool = False
    # random translation of every training image (and its label image) by up to this many
    # pixels of the network input along each axis, zero-filled (`learn.augment`); 0 = off.
    # Measured at 8 on the paper-sized forearm set: HandsNet -2.85 points at seeds 0 and 1
    # (p < 0.001 each), SegNet -1.06 mIoU points (within the interval), so it is off by default.
    shift_px: int = 0
    # mixup (`learn.augment.mixup`, classifiers only): every training batch mixed with a
    # shuffled copy of itself, images and one-hot targets alike, by lam ~ Beta(alpha, alpha);
    # 0 = off (the paper). Measured at 0.2 on the paper-sized forearm set, seeds 0-3: HandsNet
    # 92.39, 93.05, 91.34, 91.82 % against the preset's 91.82, 89.63, 91.44, 92.01 % (only seed
    # 1's gain beyond test-set luck; docs/learning.md, "Regularisers"), so it is off by default.
    mixup_alpha: float = 0.0
    # weight of an auxiliary loss (`learn.aux_types`, classifiers on a handskin dataset): a
    # linear head on the last hidden layer learns the contactor's type (hand, object: rake,
    # body: elbow, ...) beside the class; used in training only, checkpoints hold the plain
    # network. 0 = off (the paper). Measured: docs/learning.md, "Contactor types".
    aux_types_weight: float = 0.0
    # knowledge distillation (`learn.distill`, classifiers): a trained classifier's checkpoint
    # (.pt) whose flip-averaged probabilities at distill_temperature the network learns beside
    # the labels, with share distill_weight of the loss (Hinton et al., 2015); "" = off (the
    # paper). The teacher must share the task, classes, input size and canvas, and must not
    # have trained on the data's test people or objects. Measured at 0.5 and T 4 from VGG16
    # w0.25 on the floored 10x set: HandsNet 97.17 % against 97.20 % without (p = 0.89;
    # docs/learning.md, "A teacher, and no dropout"), so it is off by default.
    distill_from: str = ""
    distill_weight: float = 0.5  # share (0-1] of the loss given to the teacher's targets
    distill_temperature: float = 4.0  # softmax temperature T > 0 of teacher and student terms
    threads: int = 2  # torch CPU threads (the project's machines have 2 shared cores)
    # number format of the training forward pass: "fp32", or "bf16" to autocast convolutions and
    # matrix products to bfloat16 (torch.autocast) while weights, optimizer state, loss and
    # validation stay float32; needs a CPU with native bf16 (AVX512-BF16 / AMX, `check_precision`)
    precision: str = "fp32"
    eval_batch_size: int = 64  # images per evaluation forward pass
    # where the model trains: "cpu" (bit-reproducible from the seed), or "cuda" / "cuda:N" for a
    # GPU (a CUDA build of torch; cuDNN's kernels may differ in the last bits from run to run).
    # Batches are drawn and augmented on the CPU either way, so both see the same images.
    device: str = "cpu"

    def __post_init__(self) -> None:
        if self.model.arch not in TASK_OF_ARCH:
            raise ConfigError(
                f"unknown arch {self.model.arch!r}; choose one of: "
                f"{', '.join(sorted(TASK_OF_ARCH))}"
            )
        if not 0.0 <= self.val_fraction < 1.0:
            raise ConfigError(f"RunConfig.val_fraction must be in [0, 1), not {self.val_fraction}")
        half = min(self.model.input_size) // 2
        if not 0 <= self.shift_px <= half:
            raise ConfigError(
                f"RunConfig.shift_px={self.shift_px} is outside 0..{half} (half the smaller side "
                "of the network input, pixels). Fix: 0 (off) or a few pixels"
            )
        if self.mixup_alpha < 0 or (self.mixup_alpha and self.task != "classify"):
            raise ConfigError(
                f"RunConfig.mixup_alpha={self.mixup_alpha} (arch {self.model.arch!r}): mixup "
                "mixes class targets, so it needs alpha >= 0 and a classifier (handsnet, vgg16). "
                "Fix: mixup_alpha = 0 (off) or e.g. 0.2 with a classifier"
            )
        if self.aux_types_weight < 0 or (self.aux_types_weight and self.task != "classify"):
            raise ConfigError(
                f"RunConfig.aux_types_weight={self.aux_types_weight} (arch "
                f"{self.model.arch!r}): the type head learns what touched beside hand / "
                "non-hand, so it needs a weight >= 0 and a classifier (handsnet, vgg16). Fix: "
                "aux_types_weight = 0 (off) or e.g. 1.0 with a classifier"
            )
        if self.aux_types_weight and self.mixup_alpha:
            raise ConfigError(
                "RunConfig: aux_types_weight and mixup_alpha together would need mixed type "
                "targets, which the type head does not take. Fix: set one of them to 0"
            )
        if not 0 < self.distill_weight <= 1 or not self.distill_temperature > 0:
            raise ConfigError(
                f"RunConfig.distill_weight={self.distill_weight}, distill_temperature="
                f"{self.distill_temperature}: the teacher's share of the loss must lie in (0, 1] "
                "and the temperature be > 0. Fix: e.g. distill_weight = 0.5, "
                "distill_temperature = 4"
            )
        if self.distill_from and (self.task != "classify" or self.mixup_alpha):
            raise ConfigError(
                f"RunConfig.distill_from={self.distill_from!r} (arch {self.model.arch!r}, "
                f"mixup_alpha {self.mixup_alpha}): distillation gives each training image its "
                "teacher's class probabilities, so it needs a classifier (handsnet, vgg16) and "
                'unmixed images. Fix: distill_from = "" (off), or a classifier with '
                "mixup_alpha = 0"
            )
        if self.patience_epochs < 0 or self.threads < 1 or self.eval_batch_size < 1:
            raise ConfigError("RunConfig: patience_epochs >= 0, threads >= 1, eval_batch_size >= 1")
        if not re.fullmatch(DEVICE_PATTERN, self.device):
            raise ConfigError(
                f"RunConfig.device {self.device!r} is not a training device. Fix: device = "
                '"cpu" (the default), "cuda" or "cuda:N" (a GPU; --device)'
            )
        if self.precision not in PRECISIONS:
            raise ConfigError(
                f"RunConfig.precision {self.precision!r} is not one of {', '.join(PRECISIONS)}. "
                'Fix: precision = "fp32" (the default) or "bf16" (faster on CPUs with native '
                "bfloat16)"
            )

    @property
    def task(self) -> str:
        """``"classify"`` or ``"segment"``, from the architecture."""
        return TASK_OF_ARCH[self.model.arch]


def metric_name(task: str) -> str:
    """The validation metric that selects the best epoch: accuracy or mean IoU."""
    return "accuracy" if task == "classify" else "mean_iou"


def replace_train(run: RunConfig, **changes: object) -> RunConfig:
    """A copy of ``run`` with TrainConfig fields changed (validated)."""
    return dataclasses.replace(run, train=dataclasses.replace(run.train, **changes))


def _merge(base: dict, table: Mapping) -> dict:
    """``base`` with ``table``'s keys laid over it, recursively for sub-tables."""
    out = dict(base)
    for key, value in table.items():
        nested = isinstance(value, Mapping) and isinstance(base.get(key), dict)
        nested = nested and key != "lr_factors"
        out[key] = _merge(base[key], value) if nested else value
    return out


def run_from_dict(table: Mapping, base: RunConfig | None = None) -> RunConfig:
    """RunConfig from a nested dict (TOML tables ``[model]``, ``[train]`` and top-level keys)
    laid over ``base`` (default RunConfig()); unknown keys and bad values raise ConfigError."""
    table = _merge(to_dict(base or RunConfig()), table)
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
    table = read_toml(path)
    try:
        return run_from_dict(table, base)
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from err
