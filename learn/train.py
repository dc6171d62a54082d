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

import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn
from tqdm.auto import tqdm

from learn.augment import mixup, random_shift
from learn.aux_types import TypeHead
from learn.averaging import make_ema
from learn.checkpoint import BEST, LAST, load_checkpoint
from learn.curves import plot_history
from learn.device import check_device
from learn.distill import Distiller, make_distiller
from learn.evaluate import evaluate_tensors
from learn.fastpath import bf16_supported
from learn.finetune import load_weights, make_optimizer, make_scheduler
from learn.folder import Data, TensorData, class_weights, load_data  # noqa: F401 (re-export)
from learn.leakage import ancestry
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
from learn.run_state import (
    check_stop_epoch,
    improved,
    patience_out,
    restore,
    save,
    weights_copy,
)
from learn.tta import PAPER_VIEWS, VIEW_DIMS
from tactile.config import to_toml
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


def get_batch(
    data: TensorData, items: torch.Tensor, views: torch.Tensor
) -> tuple[torch.Tensor, ...]:
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


def train_epoch(
    model,
    data,
    loss_fn,
    optimizer,
    run: RunConfig,
    epoch: int,
    progress: bool,
    head: TypeHead | None = None,
    distiller: Distiller | None = None,
):
    """One epoch over a seeded permutation of (sample, view) pairs; returns the mean loss (with
    the type head's term, and the teacher's with a ``distiller``, `learn.distill`). Batches are
    drawn and augmented on the CPU, then moved to ``run.device``."""
    torch.manual_seed(epoch_seed(run.train.seed, epoch))
    views = views_of(run)
    order = torch.randperm(len(data.y) * len(views))
    model.train()
    total, bar = (
        0.0,
        tqdm(
            range(0, len(order), run.train.batch_size),
            disable=not progress,
            desc=f"epoch {epoch + 1}/{run.train.epochs}",
            leave=False,
        ),
    )
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


def train_step(
    model,
    loss_fn,
    optimizer,
    x: torch.Tensor,
    y: torch.Tensor,
    task: str,
    precision: str = "fp32",
    aux: tuple[TypeHead, torch.Tensor] | None = None,
    distill: tuple[Distiller, torch.Tensor] | None = None,
) -> float:
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
            raise ConfigError(
                f'precision "bf16": GPU {run.device!r} has no bfloat16. '
                'Fix: precision = "fp32" (--precision fp32)'
            )
        return
    if run.precision == "bf16" and not bf16_supported():
        raise ConfigError(
            'precision "bf16" needs a CPU with native bfloat16 (AVX512-BF16 or AMX); this '
            'one has none, so bf16 would train slower than fp32. Fix: precision = "fp32" '
            "(--precision fp32)"
        )


def build(run: RunConfig, init_from: str | Path | Mapping | None = None, num_types: int = 0):
    """Model (seeded init, optionally loaded from a checkpoint: a .pt path or its loaded dict),
    optimizer, step schedule, and with ``num_types`` a type head (`learn.aux_types`, its weights
    in an optimizer group of its own at the run's lr; else None)."""
    torch.manual_seed(run.train.seed)
    model = create_model(run.model.arch, **run.model.kwargs())
    if init_from is not None:
        start = init_from if isinstance(init_from, Mapping) else load_checkpoint(init_from)
        load_weights(model, start)
    if run.task == "classify":  # channels-last convs train ~20 % faster on CPU (oneDNN)
        model = model.to(memory_format=torch.channels_last)
    model = model.to(run.device)  # before the optimizer, whose state follows the parameters
    optimizer = make_optimizer(model, run.train)
    head = None
    if num_types:
        head = TypeHead(model, num_types, run.aux_types_weight).to(run.device)
        optimizer.add_param_group({"params": list(head.parameters())})
    return model, optimizer, make_scheduler(optimizer, run.train), head


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
    teacher: dict | None = None,
    init_checkpoint: dict | None = None,
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
    teacher : ``run.distill_from``'s checkpoint as `learn.distill.check_teacher` returned it
    (checked before the data were loaded; None checks and loads it here). init_checkpoint :
    ``init_from``'s checkpoint as `learn.finetune.check_init` loaded it (None loads it here).
    With ``run.train.ema_decay`` the weight average (``learn.averaging``) is validated, saved as
    best.pt and returned; last.pt keeps the raw weights and the average (``"ema"``) to resume.
    """
    check_precision(run)
    torch.set_num_threads(run.threads)
    out = None if out_dir is None else Path(out_dir)
    resuming = resume and out is not None and (out / LAST).is_file()
    init_ckpt = init_checkpoint  # read once for the weights and the lineage
    if init_ckpt is None and init_from is not None and not resuming:  # resuming: last.pt's
        init_ckpt = load_checkpoint(init_from)
    model, optimizer, scheduler, head = build(run, init_ckpt, _num_types(run, data))
    ema = make_ema(model, optimizer, run.train.ema_decay)
    scored = model if ema is None else ema.module  # the weights validated, selected and kept
    loss_fn = make_loss(run, data.train).to(run.device)
    val_loss_fn = (
        make_loss(run, data.train, validation=True).to(run.device)
        if run.train.label_smoothing
        else loss_fn
    )
    distiller = make_distiller(run, data, progress, teacher)
    start, best, history, best_state = 0, float("nan"), [], weights_copy(scored)
    learned_from = None  # the data records of the start and the teacher (learn.leakage.lineage)
    if resuming:
        start, best, history, best_state, first, learned_from = restore(
            out, run, model, optimizer, scheduler, ema, head
        )
        init_from = first if first not in (None, "random") else init_from
    if learned_from is None:
        learned_from = ancestry(
            init_ckpt if init_ckpt is not None else init_from,
            teacher if teacher is not None else run.distill_from,
        )
    check_stop_epoch(stop_after_epoch, start, run.train.epochs, None if out is None else out / LAST)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        (out / "run.toml").write_text(to_toml(run))
    paused = False
    for epoch in range(start, run.train.epochs):
        if on_epoch is not None:
            on_epoch(epoch, optimizer)
        row = _one_epoch(
            model,
            data,
            (loss_fn, val_loss_fn),
            optimizer,
            run,
            epoch,
            progress,
            scored,
            head,
            distiller,
        )
        scheduler.step()
        history.append(row)
        if improved(row.get("val_metric", float("nan")), best) or data.val is None:
            best = row.get("val_metric", best)
            best_state = weights_copy(scored)
            save(
                out,
                BEST,
                scored,
                optimizer,
                scheduler,
                run,
                data,
                epoch,
                best,
                history,
                init_from,
                ancestry=learned_from,
            )
        save(
            out,
            LAST,
            model,
            optimizer,
            scheduler,
            run,
            data,
            epoch,
            best,
            history,
            init_from,
            ema=ema,
            head=head,
            ancestry=learned_from,
        )
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


@flushing()
def _one_epoch(
    model,
    data: Data,
    loss_fns,
    optimizer,
    run: RunConfig,
    epoch: int,
    progress: bool,
    scored: nn.Module | None = None,
    head: TypeHead | None = None,
    distiller: Distiller | None = None,
):
    """Train one epoch and validate ``scored`` (default ``model``; the weight average when there
    is one): a history row (losses, val metric, lr of each group). ``loss_fns``: (training,
    validation) losses."""
    loss_fn, val_loss_fn = loss_fns
    tic = time.perf_counter()
    row = {"epoch": epoch + 1, "lr": [g["lr"] for g in optimizer.param_groups]}
    row["train_loss"] = train_epoch(
        model, data.train, loss_fn, optimizer, run, epoch, progress, head, distiller
    )
    if data.val is not None:
        res = evaluate_tensors(
            model if scored is None else scored,
            data.val,
            run.model.num_classes,
            run.eval_batch_size,
            val_loss_fn,
        )
        row["val_loss"], row["val_metric"] = res.loss, res.metrics[metric_name(run.task)]
    row["seconds"] = time.perf_counter() - tic
    return row


def _num_types(run: RunConfig, data: Data) -> int:
    """How many contactor types the run's type head tells apart (0: no head)."""
    if not run.aux_types_weight:
        return 0
    if data.train.types is None:
        raise ConfigError(
            "aux_types_weight is set but the training data carry no contactor "
            "types. Fix: load them with learn.train.load_data(path, run), which "
            "reads them for such a run"
        )
    return len(data.type_names)
