"""A training run's folder state: resuming from ``last.pt``, saving ``last.pt`` / ``best.pt``,
and when a run stops (``--stop-after-epoch``, ``patience_epochs``). Used by `learn.train.fit`.

    start, best, history, best_weights, init = restore(out, run, model, optimizer, scheduler)
    save(out, LAST, model, optimizer, scheduler, run, data, epoch, best, history)
"""

from __future__ import annotations

import math
from pathlib import Path

import torch
from torch import nn

from learn.checkpoint import (
    BEST,
    LAST,
    check_inputs,
    load_checkpoint,
    make_checkpoint,
    save_checkpoint,
)
from learn.folder import Data
from learn.run_config import RunConfig, run_from_dict
from tactile.config import to_dict
from tactile.errors import ConfigError


def weights_copy(model: nn.Module) -> dict[str, torch.Tensor]:
    """A detached copy of ``model``'s state dict (name -> tensor)."""
    return {k: v.detach().clone() for k, v in model.state_dict().items()}


def restore(out: Path, run: RunConfig, model, optimizer, scheduler, ema=None, head=None):
    """(start epoch, best metric, history, best weights, recorded start, recorded ancestry:
    None in checkpoints from before it was recorded) of the run in ``out``
    (last.pt); loads the weights, optimizer, schedule, weight average (``ema``) and type head
    (``head``) in place."""
    ckpt = load_checkpoint(out / LAST)
    try:  # keys added since the checkpoint was written take their defaults (the old behaviour)
        theirs = to_dict(run_from_dict(ckpt["config"]))
    except ConfigError as err:
        raise ConfigError(
            f"{out / LAST}: its configuration does not load ({err}); use a new --out"
        ) from err
    mine = to_dict(run)
    mine["train"] = {**mine["train"], "epochs": None}  # may change on resume: the schedule's
    theirs["train"] = {**theirs["train"], "epochs": None}  # length, and where the run trains
    mine["device"] = theirs["device"] = None
    if mine != theirs:
        raise ConfigError(
            f"{out / LAST} was trained with another configuration; resume with the same one "
            "(only train.epochs and device may change) or use a new --out"
        )
    check_inputs(ckpt, run.task, str(out / LAST))
    model.load_state_dict(ckpt["model"])
    optimizer.load_state_dict(ckpt["optimizer"])
    scheduler.load_state_dict(ckpt["scheduler"])
    if ema is not None:
        ema.load_state_dict(ckpt["ema"])
    if head is not None:
        head.load_state_dict(ckpt["type_head"])
    best = out / BEST
    best_state = load_checkpoint(best)["model"] if best.is_file() else weights_copy(model)
    return (
        int(ckpt["epoch"]),
        float(ckpt["best_metric"]),
        list(ckpt["history"]),
        best_state,
        ckpt.get("init"),
        ckpt.get("ancestry"),
    )


def improved(metric: float, best: float) -> bool:
    """True when ``metric`` beats ``best`` (NaN ``best``: nothing scored yet; NaN ``metric``:
    never)."""
    return not math.isnan(metric) and (math.isnan(best) or metric > best)


def check_stop(
    stop_after_epoch: int | None,
    run: RunConfig,
    out_dir: str | Path | None = None,
    resume: bool = False,
) -> None:
    """ConfigError unless ``stop_after_epoch`` ends an epoch that :func:`fit` would train for
    ``run`` (resumed from ``out_dir/last.pt`` when ``resume``): checked before data is loaded."""
    last = None if out_dir is None else Path(out_dir) / LAST
    start = int(load_checkpoint(last)["epoch"]) if resume and last and last.is_file() else 0
    check_stop_epoch(stop_after_epoch, start, run.train.epochs, last)


def check_stop_epoch(
    stop_after_epoch: int | None, start: int, epochs: int, last: Path | None
) -> None:
    """Refuse a stop epoch that could not end an epoch of this (possibly resumed) run."""
    if stop_after_epoch is None:
        return
    if not 1 <= stop_after_epoch <= epochs:
        raise ConfigError(
            f"stop after epoch {stop_after_epoch}: the run's epochs are 1 to "
            f"{epochs}. Fix: give one of them (the schedule's length is "
            "train.epochs)"
        )
    if stop_after_epoch <= start:
        raise ConfigError(
            f"{last} already holds epoch {start}, so stopping after epoch "
            f"{stop_after_epoch} would train nothing. Fix: give a later epoch, or leave the "
            "stop out to finish the run"
        )


def patience_out(history: list[dict], run: RunConfig) -> bool:
    """True when the val metric has not improved for ``patience_epochs`` epochs."""
    k = run.patience_epochs
    vals = [h.get("val_metric", float("nan")) for h in history]
    if not k or len(vals) <= k or all(math.isnan(v) for v in vals):
        return False
    return max(vals[-k:]) <= max(v for v in vals[:-k] if not math.isnan(v))


def save(
    out,
    name,
    model,
    optimizer,
    scheduler,
    run,
    data: Data,
    epoch,
    best,
    history,
    init_from=None,
    ema=None,
    head=None,
    ancestry=None,
) -> None:
    """Write ``out/name`` (``LAST`` or ``BEST``) for the epoch just trained (0-based ``epoch``);
    nothing when ``out`` is None. ``ema`` / ``head``: kept in last.pt to resume them.
    ``ancestry``: the data records of the checkpoints it started from and learned from
    (`learn.leakage.ancestry`), kept so evaluation knows what the weights have seen."""
    if out is None:
        return
    extra = {} if ema is None else {"ema": ema.state_dict()}  # last.pt: to resume the average
    if head is not None:  # last.pt: to resume the type head (best.pt holds the plain network)
        extra["type_head"] = head.state_dict()
    ckpt = make_checkpoint(
        model,
        to_dict(run),
        epoch=epoch + 1,
        best_metric=best,
        optimizer=optimizer,
        scheduler=scheduler,
        history=history,
        class_names=list(data.class_names),
        seed=run.train.seed,
        task=run.task,
        data=data.description,
        init="random" if init_from is None else str(init_from),
        ancestry=ancestry or [],
        **extra,
    )
    save_checkpoint(ckpt, out / name)
