"""Checkpoints as plain dicts (nanoGPT style), safe to read with ``torch.load(weights_only=True)``.

    ckpt = {"model": state_dict, "optimizer": state_dict, "scheduler": state_dict,
            "config": {...}, "epoch": int, "best_metric": float, "history": [...],
            "class_names": [...], "versions": {...}, "seed": int, "inputs": str}

``config`` is the resolved :class:`learn.config.RunConfig` as a JSON-able dict
(``tactile.config.to_dict``); ``epoch`` is the number of completed epochs; ``history`` holds one
dict of losses and metrics per epoch; ``inputs`` names the rule its network inputs were made
with (`learn.inputs.INPUTS`). Files are written atomically (temporary name, then
``os.replace``) so a killed run never leaves half a checkpoint.
"""

from __future__ import annotations

import errno
import os
import platform
import warnings
from collections.abc import Mapping
from importlib import metadata
from pathlib import Path

import numpy as np
import torch
from torch import nn

from learn.config import RunConfig, run_from_dict
from learn.inputs import INPUTS
from learn.models import create_model
from tactile.errors import ConfigError, DataError

LAST, BEST = "last.pt", "best.pt"  # file names in a run folder
INT8_KEY = "int8"  # the key of an int8 file's quantized network (`learn.infer.int8_file`)
REQUIRED_KEYS = ("model", "config", "epoch", "best_metric")
PACKAGES = ("numpy", "torch", "scikit-learn", "scikit-image", "h5py", "handskin")


def versions() -> dict[str, str]:
    """Python and package versions (package metadata; "absent" when not installed)."""
    out = {"python": platform.python_version(), "torch_runtime": str(torch.__version__)}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "absent"
    return out


def _plain(value: object) -> object:
    """Numpy scalars and arrays to Python numbers and lists (safe-mode loadable)."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    return value


def make_checkpoint(
    model: nn.Module,
    config: Mapping[str, object],
    *,
    epoch: int,
    best_metric: float,
    optimizer: torch.optim.Optimizer | None = None,
    scheduler: torch.optim.lr_scheduler.LRScheduler | None = None,
    **extra: object,
) -> dict[str, object]:
    """The checkpoint dict of a run after ``epoch`` completed epochs (see the module docstring).

    ``extra`` (history, class_names, seed, metrics, ...) is stored as plain Python values.
    """
    ckpt: dict[str, object] = {
        "model": {k: v.detach().cpu().clone() for k, v in model.state_dict().items()},
        "config": _plain(config),
        "epoch": int(epoch),
        "best_metric": float(best_metric),
        "versions": versions(),
        "inputs": INPUTS,
    }
    if optimizer is not None:
        ckpt["optimizer"] = optimizer.state_dict()
    if scheduler is not None:
        ckpt["scheduler"] = scheduler.state_dict()
    ckpt.update({k: _plain(v) for k, v in extra.items()})
    return ckpt


def save_checkpoint(ckpt: Mapping[str, object], path: str | Path) -> Path:
    """Write ``ckpt`` atomically to ``path`` (parents created): a temporary file, then a rename,
    so a killed run never leaves half a checkpoint. A full disk or a folder without write
    permission is a DataError naming the path; no temporary file is left."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        torch.save(dict(ckpt), tmp)
        os.replace(tmp, path)
    except (OSError, RuntimeError) as err:  # torch reports a short write as RuntimeError
        tmp.unlink(missing_ok=True)
        raise DataError(f"cannot write {path}: {_why(err)}. Fix: {_fix(err)}") from err
    return path


def _why(err: Exception) -> str:
    if (isinstance(err, OSError) and err.errno == errno.ENOSPC) or "unexpected pos" in str(err):
        return "the disk is full"
    return getattr(err, "strerror", None) or str(err).splitlines()[0]


def _fix(err: Exception) -> str:
    if isinstance(err, OSError) and err.errno in (errno.EACCES, errno.EROFS, errno.EPERM):
        return "give an --out folder you may write to"
    return "free space on that disk (a checkpoint of the presets takes 3-35 MB) or another --out"


def is_int8(ckpt: Mapping) -> bool:
    """True for a checkpoint written by ``handskin quantize`` (`learn.infer.int8_file`)."""
    return isinstance(ckpt.get(INT8_KEY), Mapping)


def refuse_int8(ckpt: Mapping, where: str | Path, why: str) -> None:
    """ConfigError when ``ckpt`` (read from ``where``) is an int8 file and the caller would run
    its float weights instead (``why``: a clause saying so)."""
    if is_int8(ckpt):
        source = ckpt[INT8_KEY].get("source") or "the float checkpoint it was made from"
        raise ConfigError(
            f"{where} is an int8 network (handskin quantize), and {why}. Fix: give {source}, "
            "or run the int8 file alone with handskin predict or handskin evaluate"
        )


def run_of(ckpt: Mapping, where: str | Path = "the checkpoint") -> RunConfig:
    """The RunConfig a checkpoint was trained with (ConfigError naming ``where`` when it used an
    option handskin no longer has)."""
    return run_from_dict(ckpt["config"], where=str(where))


def model_from_checkpoint(
    ckpt: Mapping, int8_ok: bool = False, where: str | Path = "the checkpoint"
) -> tuple[nn.Module, RunConfig]:
    """The trained model (eval mode) and the RunConfig of a checkpoint dict read from ``where``.
    An int8 file (``handskin quantize``) is refused with a ConfigError unless ``int8_ok`` (the
    caller runs its saved int8 network; the model returned is its float HandsNet)."""
    if not int8_ok:
        refuse_int8(ckpt, where, "this command runs float networks")
    run = run_of(ckpt, where)
    check_inputs(ckpt, run.task, str(where))
    model = create_model(run.model.arch, **run.model.kwargs())
    model.load_state_dict(ckpt["model"])
    return model.eval(), run


def inputs_stale(ckpt: Mapping, task: str) -> bool:
    """True for a segmenter trained before its inputs kept their labels' support
    (`learn.inputs`): it would be scored on inputs it never saw. Classifiers are unaffected."""
    return task == "segment" and ckpt.get("inputs") != INPUTS


def check_inputs(ckpt: Mapping, task: str, where: str = "the checkpoint") -> None:
    """DataError naming the fix when `inputs_stale`."""
    if inputs_stale(ckpt, task):
        raise DataError(
            f"{where} is a segmenter trained on inputs blurred past their labels' support "
            f"(before input rule {INPUTS!r}); its scores would be wrong on today's inputs. "
            "Fix: retrain it with handskin train (or delete it from the experiment's models "
            "folder so the experiment retrains it)"
        )


def load_checkpoint(path: str | Path) -> dict[str, object]:
    """Read a checkpoint in ``torch.load`` safe mode; DataError naming the file and the fix."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"no checkpoint at {path}. Fix: give a .pt file written by handskin train")
    try:
        with warnings.catch_warnings():  # an int8 file's quantized tensors: torch's deprecations
            warnings.filterwarnings("ignore", ".*(TypedStorage|quantized tensor creation)")
            ckpt = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # unpickling errors come in many types
        why = str(err).splitlines()[0] if str(err) else ""
        why = "not a PyTorch file" if "Weights only load failed" in why or not why else why
        raise DataError(
            f"{path} is not a readable checkpoint ({type(err).__name__}: {why}). Fix: give a .pt "
            "file written by handskin train (a copy cut short or from another program fails so)"
        ) from err
    missing = [k for k in REQUIRED_KEYS if not isinstance(ckpt, Mapping) or k not in ckpt]
    if missing:
        raise DataError(f"{path} lacks {missing}; it was not written by handskin train")
    return dict(ckpt)
