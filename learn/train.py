"""The training loop (nanoGPT style): one readable ``fit`` over in-memory tensors.

    run = RunConfig(model=ModelConfig("handsnet", 2), train=TrainConfig(epochs=80))
    data = load_data("out/forearm", run)                  # train / val (subject-disjoint) / test
    result = fit(run, data, "runs/handsnet")             # last.pt, best.pt, curves.png, run.toml

Images of the training split are read once (``learn.data`` / ``learn.folder``, resized to
``run.model.input_size``) and kept as ``(S, 1, h, w)`` float32 tensors; every epoch draws a
seeded permutation of the ``3 S`` (sample, view) pairs — the paper's threefold augmentation:
original, horizontal flip, vertical flip; ``rot180`` adds both flips, a 180-degree turn, as a
fourth view — and ``get_batch`` gathers and flips them (``shift_px`` then moves each at random,
`learn.augment`; ``mixup_alpha`` mixes a classifier's batch with itself; ``aux_types_weight``
adds a contactor-type loss, `learn.aux_types`; ``distill_from`` a trained teacher's soft targets,
`learn.distill`). Epoch ``e``
reseeds torch from ``(seed, e)``, so a resumed run equals an uninterrupted one on CPU.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn
from tqdm.auto import tqdm

from learn.augment import mixup, random_shift
from learn.aux_types import TypeHead
from learn.averaging import make_ema
from learn.checkpoint import (
    BEST,
    LAST,
    check_inputs,
    load_checkpoint,
    make_checkpoint,
    save_checkpoint,
)
from learn.device import check_device
from learn.distill import Distiller, make_distiller
from learn.evaluate import evaluate_tensors, plot_history
from learn.fastpath import bf16_supported
from learn.finetune import load_weights, make_optimizer, make_scheduler
from learn.folder import Data, TensorData, class_weights, load_data  # noqa: F401 (re-export)
from learn.losses import SegmentationLoss
from learn.models import create_model
from learn.numerics import flushing
from learn.run_config import (  # noqa: F401 (re-exported: learn.train is where runs are made)
    PRECISIONS,
    TASK_OF_ARCH,
    RunConfig,
    load_run_config,
    metric_name,
    replace_train,
    run_from_dict,
)
from learn.tta import PAPER_VIEWS, VIEW_DIMS
from tactile.config import to_dict, to_toml
from tactile.errors import ConfigError


@dataclass
class FitResult:
    """What :func:`fit` returns: the trained model (best epoch's weights if validated)."""

    model: nn.Module
    history: list[dict[str, float]]
    best_metric: float
    out_dir: Path | None
    paused: bool = False  # stopped by ``stop_after_epoch`` before the schedule's last epoch


def epoch_seed(seed: int, epoch: int) -> int:
    """Seed of epoch ``epoch`` (shuffling and dropout), a pure function of the run seed."""
    return (int(seed) * 1_000_003 + int(epoch)) % (2**63)


def flip_views(x: torch.Tensor, views: torch.Tensor) -> torch.Tensor:
    """Apply view 1 (columns reversed) / 2 (rows reversed) / 3 (both: a 180-degree turn) per
    item of ``x`` (B, ..., H, W) (``learn.tta.VIEW_DIMS``); view 0 leaves an item as it is."""
    x = x.clone()
    for view, dims in VIEW_DIMS.items():
        sel = views == view
        if dims and sel.any():
            x[sel] = x[sel].flip(dims)
    return x


def views_of(run: RunConfig) -> torch.Tensor:
    """(V,) int64 ids (`flip_views`) of the views each training sample is shown in: 0; 1 and 2
    with ``run.flips`` (the paper's three); 3 with ``run.rot180``."""
    return torch.tensor([*(PAPER_VIEWS if run.flips else (0,)), *((3,) if run.rot180 else ())])


def get_batch(data: TensorData, items: torch.Tensor,
              views: torch.Tensor) -> tuple[torch.Tensor, ...]:  # fmt: skip
    """Images (B, 1, h, w) and targets (B,) or (B, h, w) of items ``sample * V + k``: sample
    ``sample`` in view ``views[k]`` (``views`` (V,) from `views_of`)."""
    sample, view = items // len(views), views[items % len(views)]
    x, y = data.x[sample], data.y[sample]
    return flip_views(x, view), (flip_views(y, view) if y.ndim == 3 else y)


def make_loss(run: RunConfig, train: TensorData, validation: bool = False) -> nn.Module:
    """The configured loss; weighted CE takes median-frequency weights of the training targets.
    ``validation``: without label smoothing, so validation losses compare across runs."""
    name = run.train.loss
    if run.task == "classify" and name.endswith("dice"):
        raise ConfigError(f"loss {name!r} is for segmentation; use ce or weighted_ce")
    weights = class_weights(train.y, run.model.num_classes) if name == "weighted_ce" else None
    return SegmentationLoss(name, weights, 0.0 if validation else run.train.label_smoothing)


def train_epoch(model, data, loss_fn, optimizer, run: RunConfig, epoch: int, progress: bool,
                head: TypeHead | None = None, distiller: Distiller | None = None):  # fmt: skip
    """One epoch over a seeded permutation of (sample, view) pairs; returns the mean loss (with
    the type head's term, and the teacher's with a ``distiller``, `learn.distill`). Batches are
    drawn and augmented on the CPU, then moved to ``run.device``."""
    torch.manual_seed(epoch_seed(run.train.seed, epoch))
    views = views_of(run)
    order = torch.randperm(len(data.y) * len(views))
    model.train()
    total, bar = 0.0, tqdm(range(0, len(order), run.train.batch_size), disable=not progress,
                           desc=f"epoch {epoch + 1}/{run.train.epochs}", leave=False)  # fmt: skip
    for start in bar:
        items = order[start : start + run.train.batch_size]
        x, y = get_batch(data, items, views)
        x, y = random_shift(x, y, run.shift_px)
        x, y = mixup(x, y, run.mixup_alpha, run.model.num_classes)
        x, y = x.to(run.device), y.to(run.device)
        aux = None if head is None else (head, data.types[items // len(views)].to(run.device))
        soft = None if distiller is None else (distiller, items // len(views))
        value = train_step(model, loss_fn, optimizer, x, y, run.task, run.precision, aux, soft)
        total += value * len(y)
        bar.set_postfix(loss=f"{value:.4f}")
    return total / len(order)


def train_step(model, loss_fn, optimizer, x: torch.Tensor, y: torch.Tensor, task: str,
               precision: str = "fp32",
               aux: tuple[TypeHead, torch.Tensor] | None = None,
               distill: tuple[Distiller, torch.Tensor] | None = None) -> float:  # fmt: skip
    """One optimisation step on images ``x`` (B, 1, h, w) and targets ``y``; returns the loss.
    ``aux``: a type head and the batch's type ids (B,), whose weighted loss is added.
    ``distill``: a `learn.distill.Distiller` and the batch's training-sample indices (B,); the
    loss becomes its mix of the labels' loss and the teacher's soft targets.

    Classifiers get channels-last input (their weights are channels-last, see :func:`build`).
    ``precision="bf16"`` runs the forward pass under bfloat16 autocast (`RunConfig.precision`)
    on the device of ``x``; the loss is taken on float32 logits.
    """
    if task == "classify":
        x = x.contiguous(memory_format=torch.channels_last)
    with torch.autocast(x.device.type, dtype=torch.bfloat16, enabled=precision == "bf16"):
        if aux is None:
            out = model(x)
        else:
            with aux[0].capture(model):
                out = model(x)
            type_logits = aux[0]()
    loss = loss_fn(out.float(), y)
    if distill is not None:
        loss = distill[0].loss(loss, out.float(), distill[1])
    if aux is not None:
        loss = loss + aux[0].loss(type_logits, aux[1])
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    optimizer.step()
    return loss.item()


def check_precision(run: RunConfig) -> None:
    """Raise ConfigError when the run cannot train where and as asked: its device is absent
    (:func:`check_device`), or ``run.precision`` is "bf16" on a CPU without native bfloat16
    kernels (autocast would emulate them and train slower than float32) or on a GPU without
    bfloat16."""
    check_device(run.device)
    if run.precision == "bf16" and run.device != "cpu":
        if not torch.cuda.is_bf16_supported():
            raise ConfigError(f"precision \"bf16\": GPU {run.device!r} has no bfloat16. "
                              'Fix: precision = "fp32" (--precision fp32)')  # fmt: skip
        return
    if run.precision == "bf16" and not bf16_supported():
        raise ConfigError(
            "precision \"bf16\" needs a CPU with native bfloat16 (AVX512-BF16 or AMX); this "
            "one has none, so bf16 would train slower than fp32. Fix: precision = \"fp32\" "
            "(--precision fp32)"
        )


def build(run: RunConfig, init_from: str | Path | None = None, num_types: int = 0):
    """Model (seeded init, optionally loaded from a checkpoint), optimizer, step schedule, and
    with ``num_types`` a type head (`learn.aux_types`, its weights in an optimizer group of its
    own at the run's lr; else None)."""
    torch.manual_seed(run.train.seed)
    model = create_model(run.model.arch, **run.model.kwargs())
    if init_from is not None:
        load_weights(model, load_checkpoint(init_from))
    if run.task == "classify":  # channels-last convs train ~20 % faster on CPU (oneDNN)
        model = model.to(memory_format=torch.channels_last)
    model = model.to(run.device)  # before the optimizer, whose state follows the parameters
    optimizer = make_optimizer(model, run.train)
    head = None
    if num_types:
        head = TypeHead(model, num_types, run.aux_types_weight).to(run.device)
        optimizer.add_param_group({"params": list(head.parameters())})
    return model, optimizer, make_scheduler(optimizer, run.train), head


def _state(model: nn.Module) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in model.state_dict().items()}


def _restore(out: Path, run: RunConfig, model, optimizer, scheduler, ema=None, head=None):
    """(start epoch, best metric, history, best weights, recorded start) of the run in ``out``
    (last.pt); loads the weights, optimizer, schedule, weight average (``ema``) and type head
    (``head``) in place."""
    ckpt = load_checkpoint(out / LAST)
    try:  # keys added since the checkpoint was written take their defaults (the old behaviour)
        theirs = to_dict(run_from_dict(ckpt["config"]))
    except ConfigError as err:
        raise ConfigError(f"{out / LAST}: its configuration does not load ({err}); use a new "
                          "--out") from err  # fmt: skip
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
    best_state = load_checkpoint(out / BEST)["model"] if (out / BEST).is_file() else _state(model)
    return (int(ckpt["epoch"]), float(ckpt["best_metric"]), list(ckpt["history"]), best_state,
            ckpt.get("init"))  # fmt: skip


def _improved(metric: float, best: float) -> bool:
    return not math.isnan(metric) and (math.isnan(best) or metric > best)


def fit(
    run: RunConfig,
    data: Data,
    out_dir: str | Path | None = None,
    *,
    resume: bool = False,
    init_from: str | Path | None = None,
    progress: bool = True,
    stop_after_epoch: int | None = None,
    on_epoch: Callable[[int, torch.optim.Optimizer], None] | None = None,
) -> FitResult:
    """Train ``run`` on ``data.train``, validating on ``data.val`` (if any) after every epoch.

    out_dir : run folder for ``last.pt`` (every epoch), ``best.pt`` (best val metric, or the last
    epoch without validation), ``curves.png`` and ``run.toml``; None writes nothing.
    resume : continue from ``out_dir/last.pt``. init_from : fine-tune from any checkpoint (the
    weights whose names and shapes match; ``run.train.lr_factors`` scale per-layer lrs).
    stop_after_epoch : stop once this epoch (1-based, counted from the run's start, so across
    resumes) is done, to split a long run; the schedule stays that of ``run.train.epochs`` and
    ``resume`` continues it. ConfigError if it is below 1 or not after the resumed epoch.
    on_epoch : called as ``on_epoch(epoch, optimizer)`` before each epoch's training.
    With ``run.train.ema_decay`` the weight average (``learn.averaging``) is validated, saved as
    best.pt and returned; last.pt keeps the raw weights and the average (``"ema"``) to resume.
    """
    check_precision(run)
    torch.set_num_threads(run.threads)
    out = None if out_dir is None else Path(out_dir)
    model, optimizer, scheduler, head = build(run, init_from, _num_types(run, data))
    ema = make_ema(model, optimizer, run.train.ema_decay)
    scored = model if ema is None else ema.module  # the weights validated, selected and kept
    loss_fn = make_loss(run, data.train).to(run.device)
    val_loss_fn = (make_loss(run, data.train, validation=True).to(run.device)
                   if run.train.label_smoothing else loss_fn)  # fmt: skip
    distiller = make_distiller(run, data, progress)
    start, best, history, best_state = 0, float("nan"), [], _state(scored)
    if resume and out is not None and (out / LAST).is_file():
        start, best, history, best_state, first = _restore(out, run, model, optimizer, scheduler,
                                                           ema, head)  # fmt: skip
        init_from = first if first not in (None, "random") else init_from
    _check_stop(stop_after_epoch, start, run.train.epochs, None if out is None else out / LAST)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "run.toml").write_text(to_toml(run))
    paused = False
    for epoch in range(start, run.train.epochs):
        if on_epoch is not None:
            on_epoch(epoch, optimizer)
        row = _one_epoch(model, data, (loss_fn, val_loss_fn), optimizer, run, epoch, progress,
                         scored, head, distiller)  # fmt: skip
        scheduler.step()
        history.append(row)
        if _improved(row.get("val_metric", float("nan")), best) or data.val is None:
            best = row.get("val_metric", best)
            best_state = _state(scored)
            _save(out, BEST, scored, optimizer, scheduler, run, data, epoch, best, history,
                  init_from)
        _save(out, LAST, model, optimizer, scheduler, run, data, epoch, best, history, init_from,
              ema=ema, head=head)
        if out is not None:
            title = f"{run.model.arch}, seed {run.train.seed}"
            best_epoch = next((h["epoch"] for h in history if h.get("val_metric") == best), None)
            plot_history(history, out / "curves.png", title, metric_name(run.task), best_epoch)
        if patience_out(history, run):
            break
        if stop_after_epoch is not None and epoch + 1 >= stop_after_epoch:
            paused = epoch + 1 < run.train.epochs
            break
    if data.val is not None:
        scored.load_state_dict(best_state)
    return FitResult(scored.to("cpu"), history, best, out, paused)


def check_stop(stop_after_epoch: int | None, run: RunConfig, out_dir: str | Path | None = None,
               resume: bool = False) -> None:  # fmt: skip
    """ConfigError unless ``stop_after_epoch`` ends an epoch that :func:`fit` would train for
    ``run`` (resumed from ``out_dir/last.pt`` when ``resume``): checked before data is loaded."""
    last = None if out_dir is None else Path(out_dir) / LAST
    start = int(load_checkpoint(last)["epoch"]) if resume and last and last.is_file() else 0
    _check_stop(stop_after_epoch, start, run.train.epochs, last)


def _check_stop(stop_after_epoch: int | None, start: int, epochs: int, last: Path | None) -> None:
    """Refuse a stop epoch that could not end an epoch of this (possibly resumed) run."""
    if stop_after_epoch is None:
        return
    if not 1 <= stop_after_epoch <= epochs:
        raise ConfigError(f"stop after epoch {stop_after_epoch}: the run's epochs are 1 to "
                          f"{epochs}. Fix: give one of them (the schedule's length is "
                          "train.epochs)")  # fmt: skip
    if stop_after_epoch <= start:
        raise ConfigError(
            f"{last} already holds epoch {start}, so stopping after epoch "
            f"{stop_after_epoch} would train nothing. Fix: give a later epoch, or leave the "
            "stop out to finish the run"
        )


@flushing()
def _one_epoch(model, data: Data, loss_fns, optimizer, run: RunConfig, epoch: int, progress: bool,
               scored: nn.Module | None = None, head: TypeHead | None = None,
               distiller: Distiller | None = None):  # fmt: skip
    """Train one epoch and validate ``scored`` (default ``model``; the weight average when there
    is one): a history row (losses, val metric, lr of each group). ``loss_fns``: (training,
    validation) losses."""
    loss_fn, val_loss_fn = loss_fns
    tic = time.perf_counter()
    row = {"epoch": epoch + 1, "lr": [g["lr"] for g in optimizer.param_groups]}
    row["train_loss"] = train_epoch(model, data.train, loss_fn, optimizer, run, epoch, progress,
                                    head, distiller)  # fmt: skip
    if data.val is not None:
        res = evaluate_tensors(model if scored is None else scored, data.val,
                               run.model.num_classes, run.eval_batch_size, val_loss_fn)
        row["val_loss"], row["val_metric"] = res.loss, res.metrics[metric_name(run.task)]
    row["seconds"] = time.perf_counter() - tic
    return row


def _num_types(run: RunConfig, data: Data) -> int:
    """How many contactor types the run's type head tells apart (0: no head)."""
    if not run.aux_types_weight:
        return 0
    if data.train.types is None:
        raise ConfigError("aux_types_weight is set but the training data carry no contactor "
                          "types. Fix: load them with learn.train.load_data(path, run), which "
                          "reads them for such a run")  # fmt: skip
    return len(data.type_names)


def patience_out(history: list[dict], run: RunConfig) -> bool:
    """True when the val metric has not improved for ``patience_epochs`` epochs."""
    k = run.patience_epochs
    vals = [h.get("val_metric", float("nan")) for h in history]
    if not k or len(vals) <= k or all(math.isnan(v) for v in vals):
        return False
    return max(vals[-k:]) <= max(v for v in vals[:-k] if not math.isnan(v))


def _save(out, name, model, optimizer, scheduler, run, data: Data, epoch, best, history,
          init_from=None, ema=None, head=None) -> None:  # fmt: skip
    if out is None:
        return
    extra = {} if ema is None else {"ema": ema.state_dict()}  # last.pt: to resume the average
    if head is not None:  # last.pt: to resume the type head (best.pt holds the plain network)
        extra["type_head"] = head.state_dict()
    ckpt = make_checkpoint(
        model, to_dict(run), epoch=epoch + 1, best_metric=best, optimizer=optimizer,
        scheduler=scheduler, history=history, class_names=list(data.class_names),
        seed=run.train.seed, task=run.task, data=data.description,
        init="random" if init_from is None else str(init_from), **extra,
    )  # fmt: skip
    save_checkpoint(ckpt, out / name)
