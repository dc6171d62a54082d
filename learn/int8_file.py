"""int8 HandsNet files: a checkpoint that carries its calibrated 8-bit network, written once by
``handskin quantize`` and run by ``handskin predict`` and ``handskin evaluate`` without
calibrating again.

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
float network (ensembles, experiments) refuse it (`refuse_int8`).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path

import torch
from torch import nn

from learn.quantize import BACKEND, Int8Classifier, int8_skeleton, load_int8_state
from tactile.errors import ConfigError, DataError

#: The checkpoint key of the saved int8 network.
INT8_KEY = "int8"
#: Float-checkpoint keys an int8 file leaves out (training state, not the network).
TRAINING_STATE = ("optimizer", "scheduler", "ema")


def is_int8(ckpt: Mapping) -> bool:
    """True for a checkpoint written by ``handskin quantize``."""
    return isinstance(ckpt.get(INT8_KEY), Mapping)


def refuse_int8(ckpt: Mapping, where: str | Path, why: str) -> None:
    """ConfigError when ``ckpt`` (read from ``where``) is an int8 file and the caller would run
    its float weights instead (``why``: a clause saying so, e.g. "this command runs float
    networks")."""
    if is_int8(ckpt):
        source = ckpt[INT8_KEY].get("source") or "the float checkpoint it was made from"
        raise ConfigError(
            f"{where} is an int8 network (handskin quantize), and {why}. Fix: "
            f"give {source}, or run the int8 file alone with handskin predict or "
            "handskin evaluate"
        )


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
