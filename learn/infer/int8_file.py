"""int8 HandsNet from a checkpoint: calibrated on training images, or read from an int8 file (a
checkpoint that carries its calibrated 8-bit network, written once by ``handskin quantize`` and
run by ``handskin predict`` and ``handskin evaluate`` without calibrating again).

    ckpt = load_checkpoint("runs/hn/best.pt")
    saved = int8_checkpoint(ckpt, quantize_int8(model, calib), "data/paper", len(calib))
    save_checkpoint(saved, "runs/hn/best_int8.pt")
    net = int8_from_saved(model, load_checkpoint("runs/hn/best_int8.pt"))  # same bits

The file is the float checkpoint (configuration, class names, history, training data, float
weights: ``--init`` of ``handskin train`` fine-tunes from them) without its optimizer state,
plus ``ckpt["int8"]``::

    {"model": state_dict of the int8 network (qint8 weights, float32 scales, int64 zero
     points), "backend": "onednn", "torch": version that wrote it,
     "calibration": {"data": path, "images": count, "split": "train", "seed": int},
     "source": path of the float checkpoint}

It loads with ``torch.load(weights_only=True)`` like any checkpoint. Tools that would run the
float network (ensembles, experiments) refuse it
(`learn.train.checkpoint.refuse_int8`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import torch
from torch import nn

from learn.data.load import materialize, open_split
from learn.infer.quantize import (
    BACKEND,
    Int8Classifier,
    int8_skeleton,
    load_int8_state,
    quantize_int8,
    traceable_body,
)
from learn.train.checkpoint import INT8_KEY, is_int8
from tactile.errors import ConfigError, DataError

#: Float-checkpoint keys an int8 file leaves out (training state, not the network).
TRAINING_STATE = ("optimizer", "scheduler")


def int8_checkpoint(
    ckpt: Mapping,
    net: Int8Classifier,
    calibration_data: str | Path,
    n_images: int,
    source: str | Path | None = None,
) -> dict:
    """The int8 file's dict: float checkpoint ``ckpt`` without its training state, plus ``net``
    (`learn.quantize.quantize_int8` of its model, calibrated on ``n_images`` train-split images
    of ``calibration_data``; ``source``: the float checkpoint's path)."""
    if is_int8(ckpt):
        raise ConfigError(
            "the checkpoint is already an int8 network. Fix: quantize the float "
            f"checkpoint it was made from ({ckpt[INT8_KEY].get('source')})"
        )
    out = {k: v for k, v in ckpt.items() if k not in TRAINING_STATE}
    seed = ((ckpt.get("config") or {}).get("train") or {}).get("seed")
    out[INT8_KEY] = {
        "model": net.state_dict(),  # keeps its _metadata: the packed layers' format versions
        "backend": BACKEND,
        "torch": str(torch.__version__),
        "calibration": {
            "data": str(calibration_data),
            "images": int(n_images),
            "split": "train",
            "seed": seed,
        },
        "source": None if source is None else str(source),
    }
    return out


def int8_from_saved(model: nn.Module, ckpt: Mapping) -> Int8Classifier:
    """The int8 network stored in ``ckpt`` (an int8 file; ``model``: its float HandsNet from
    `learn.checkpoint.model_from_checkpoint`, which gives the architecture). DataError naming
    the fix when the stored network does not fit this PyTorch's quantized graph."""
    saved = ckpt[INT8_KEY]
    try:
        return load_int8_state(int8_skeleton(model), saved["model"])
    except (RuntimeError, KeyError) as err:
        raise DataError(
            f"the int8 network in this file (written by torch {saved.get('torch')}) "
            f"does not load into torch {torch.__version__}'s quantized HandsNet "
            f"({str(err).splitlines()[0]}). Fix: quantize the float checkpoint "
            f"again: handskin quantize {saved.get('source') or 'BEST.pt'}"
        ) from err


def calibration_note(ckpt: Mapping) -> dict:
    """What a report says of a saved int8 network's calibration (JSON-able)."""
    cal = ckpt[INT8_KEY]["calibration"]
    return {
        "backend": ckpt[INT8_KEY]["backend"],
        "calibration_images": cal["images"],
        "calibration_split": cal["split"],
        "calibration_data": cal["data"],
        "saved": True,
    }


#: Calibration images drawn from the training split by `calibration_images` (count).
N_CALIBRATION = 512


def calibration_images(
    data_path, run, hand_classes: tuple[str, ...] | None, n: int = N_CALIBRATION
) -> torch.Tensor:
    """``n`` images (n, 1, h, w) of the train split of a dataset or image folder, drawn by the
    run's seed, at the run's input size (``run``: the checkpoint's `RunConfig`)."""
    split = open_split(
        data_path,
        "train",
        run.task,
        run.model.input_size,
        hand_classes,
        run.train.seed,
        run.model.canvas_mm,
    )
    gen = torch.Generator().manual_seed(run.train.seed)
    pick = torch.randperm(len(split), generator=gen)[:n].sort().values
    return materialize(torch.utils.data.Subset(split, pick.tolist()), "int8 calibration").x


def calibration_source(ckpt: dict, calibration: str | Path | None = None) -> Path:
    """Where a checkpoint's int8 copy takes its calibration images: ``calibration`` (a dataset
    or image folder) or, if None, the data it was trained on (``ckpt["data"]["path"]``).
    ConfigError naming the fix when that is not on this machine."""
    recorded = (ckpt.get("data") or {}).get("path")
    where = Path(calibration) if calibration is not None else Path(recorded) if recorded else None
    if where is None or not where.exists():
        what = (
            f"--calibration {calibration} was not found"
            if calibration is not None
            else f"the checkpoint's training data {recorded} is not here"
            if recorded
            else "the checkpoint does not say what it was trained on"
        )
        raise ConfigError(
            f"int8 needs training images to set its activation ranges; {what}. "
            "Fix: pass --calibration DATASET (a dataset or image folder of the "
            "same skin; its train split is used)"
        )
    return where


def int8_from_checkpoint(
    model: nn.Module, run, ckpt: dict, calibration: str | Path | None = None
) -> Int8Classifier:
    """The int8 copy of a checkpoint's HandsNet ``model`` (``run``: its `RunConfig`, both from
    `learn.train.checkpoint.model_from_checkpoint`), calibrated on `N_CALIBRATION` images
    of the train split of `calibration_source`. An int8 file (``handskin quantize``,
    `learn.int8_file`) gives its saved network, calibrated when it was written. ConfigError,
    before the images are read, for another network, when the calibration data is not on this
    machine, or for ``calibration`` given with an int8 file."""
    if is_int8(ckpt) and calibration is not None:
        raise ConfigError(
            "--calibration: this classifier is an int8 file, calibrated on "
            f"{ckpt[INT8_KEY]['calibration']['data']} when it was written. "
            "Fix: drop --calibration, or quantize its float checkpoint again "
            "with handskin quantize --calibration"
        )
    return int8_with_note(model, run, ckpt, calibration)[0]


def int8_with_note(
    model: nn.Module,
    run,
    ckpt: dict,
    calibration: str | Path | None = None,
    hand_classes: tuple[str, ...] | None = None,
) -> tuple[Int8Classifier, dict]:
    """`int8_from_checkpoint` and what a report says of its calibration (JSON-able: backend,
    image count, split; for an int8 file also its data and ``saved``). An int8 file gives its
    saved network and ``calibration`` is not read. ``hand_classes``: of an image folder
    (default: the checkpoint's)."""
    traceable_body(model)
    if is_int8(ckpt):  # calibrated when it was written; ``calibration`` is not read
        return int8_from_saved(model, ckpt), calibration_note(ckpt)
    where = calibration_source(ckpt, calibration)
    hand = hand_classes or (ckpt.get("data") or {}).get("hand_classes")
    calib = calibration_images(where, run, hand and tuple(hand))
    note = {"backend": BACKEND, "calibration_images": len(calib), "calibration_split": "train"}
    return quantize_int8(model, calib), note
