"""A training run's folder state: resuming from ``last.pt``, saving ``last.pt`` / ``best.pt``,
and when a run stops (``--stop-after-epoch``, ``patience_epochs``). Used by
`learn.train.loop.fit`.

    start, best, history, best_weights, init = restore(out, run, model, optimizer, scheduler)
    save(out, LAST, model, optimizer, scheduler, run, data, epoch, best, history)
"""

from __future__ import annotations

import math
from pathlib import Path

import torch
from torch import nn

from learn.config import RunConfig
from learn.data.load import Data, fingerprint
from learn.train.checkpoint import (
    BEST,
    LAST,
    check_inputs,
    load_checkpoint,
    make_checkpoint,
    run_of,
    save_checkpoint,
)
from tactile.config import to_dict
from tactile.errors import ConfigError


def weights_copy(model: nn.Module) -> dict[str, torch.Tensor]:
    """A detached copy of ``model``'s state dict (name -> tensor)."""
    return {k: v.detach().clone() for k, v in model.state_dict().items()}


def restore(out: Path, run: RunConfig, model, optimizer, scheduler):
    """(start epoch, best metric, history, best weights, recorded start) of the run in ``out``
    (last.pt); loads the weights, optimizer and schedule in place."""
    ckpt = load_checkpoint(out / LAST)
    try:  # keys added since the checkpoint was written take their defaults
        theirs = to_dict(run_of(ckpt, out / LAST))
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
    best = out / BEST
    best_state = load_checkpoint(best)["model"] if best.is_file() else weights_copy(model)
    return (
        int(ckpt["epoch"]),
        float(ckpt["best_metric"]),
        list(ckpt["history"]),
        best_state,
        ckpt.get("init"),
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
            f"--stop-after-epoch {stop_after_epoch}: the run's epochs are 1 to "
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
    out: Path | None,
    name: str,
    model,
    optimizer,
    scheduler,
    run: RunConfig,
    data: Data,
    epoch: int,
    best: float,
    history: list[dict],
    init_from=None,
) -> None:
    """Write ``out/name`` (``LAST`` or ``BEST``) for the epoch just trained (0-based ``epoch``);
    nothing when ``out`` is None."""
    if out is None:
        return
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
    )
    save_checkpoint(ckpt, out / name)


def check_run_folder(out: Path, resume: bool, data: Path) -> None:
    """Refuse, before any work, a training run that would write over what ``out`` holds:
    a fresh start over a run (last.pt), best weights without the state to resume them (best.pt
    alone: neither a fresh start nor --resume may replace them), --resume with nothing to
    resume, or --resume on other data than the run's."""
    last, best = out / LAST, out / BEST
    if best.is_file() and not last.is_file():
        raise ConfigError(
            f"{out} holds {BEST} but no {LAST}: the weights of a run that cannot be resumed, "
            f"which training would write over. Fix: move it away first (mv {best} "
            f"{out.parent / (out.name + '_best.pt')}), or give another --out"
        )
    if not last.is_file():
        if resume:
            raise ConfigError(
                f"--resume: {out} holds no {LAST}, so there is no run to resume. Fix: leave "
                "--resume out to start a new run there, or give the --out of the run to resume"
            )
        return
    held = load_checkpoint(last)
    if not resume:
        raise ConfigError(
            f"{out} already holds a run ({held['config']['model']['arch']}, {held['epoch']} "
            "epoch(s) done); training afresh would write over it. Fix: --resume to continue "
            "it, or another --out"
        )
    theirs = (held.get("data") or {}).get("path")
    if theirs is not None and Path(theirs).resolve() != Path(data).resolve():
        raise ConfigError(
            f"--resume: the run in {out} trains on {theirs}, not {data}. Fix: resume it on "
            f"{theirs}, or start a run on {data} in another --out"
        )
    check_same_data(held, data, f"--resume: the run in {out}")


def check_same_data(held: dict, data: str | Path | None, who: str) -> None:
    """Refuse a run (checkpoint dict ``held``) trained on a dataset at ``data``'s path whose
    fingerprint has changed since: regenerated there with other settings, its images are not
    the ones the run learnt from. Runs of folders, or of datasets older than fingerprints, pass."""
    stored = held.get("data") or {}
    theirs = stored.get("fingerprint")
    now = None if data is None else fingerprint(data)
    if theirs is not None and now is not None and theirs != now:
        raise ConfigError(
            f"{who} trained on {stored.get('path', 'a dataset')} (fingerprint {theirs[:12]}); "
            f"{data} is another dataset (fingerprint {now[:12]}), generated with other settings, "
            "so going on would mix two datasets in one network. Fix: train afresh in another "
            "--out (or --models) folder, or move that run away"
        )
