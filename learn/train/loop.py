"""The training loop, in one sitting: batch, step, validate, checkpoint.

    run = preset_run("handsnet")
    data = load_data("out/forearm", run)          # train / val (subject-disjoint) / test
    result = fit(run, data, "runs/handsnet")      # last.pt, best.pt, curves.png, run.toml

The training images live in memory as ``(S, 1, h, w)`` float32 tensors (sequences as
``(S, T, 1, h, w)``). Every epoch draws a seeded permutation of the ``V S`` (sample, view) pairs
— the paper's threefold augmentation: original, columns reversed, rows reversed
(``run.flips``) — and ``get_batch`` gathers and flips them, swapping mirror classes (a push to
the left seen mirrored is a push to the right: ``TensorData.mirror``). Epoch ``e`` reseeds
torch from ``(seed, e)``, so a resumed run equals an uninterrupted one on the CPU, to the bit.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import torch
from torch import nn
from tqdm.auto import tqdm

from learn.config import RunConfig, metric_name
from learn.data.load import Data, TensorData
from learn.inputs import PAPER_VIEWS, flip_view, targets_in_view
from learn.models import create_model
from learn.numerics import flushing
from learn.train.checkpoint import BEST, LAST, load_checkpoint
from learn.train.curves import plot_history
from learn.train.device import check_precision
from learn.train.losses import BothLoss, SegmentationLoss, class_weights
from learn.train.optim import load_weights, make_optimizer, make_scheduler
from learn.train.state import check_stop_epoch, improved, patience_out, restore, save, weights_copy
from learn.train.validation import evaluate_tensors
from tactile.config import to_toml
from tactile.files import write_text_atomic


@dataclass
class FitResult:
    """What :func:`fit` returns: the trained model (the best epoch's weights if validated)."""

    model: nn.Module
    history: list[dict[str, float]]
    best_metric: float
    out_dir: Path | None
    paused: bool = False  # stopped by ``stop_after_epoch`` before the schedule's last epoch


def epoch_seed(seed: int, epoch: int) -> int:
    """Seed of epoch ``epoch`` (shuffling and dropout), a pure function of the run seed."""
    return (int(seed) * 1_000_003 + int(epoch)) % (2**63)


def views_of(run: RunConfig) -> torch.Tensor:
    """(V,) int64 ids (`learn.inputs.VIEW_DIMS`) of the views each sample is shown in."""
    return torch.tensor(PAPER_VIEWS if run.flips else (0,))


def get_batch(data: TensorData, items: torch.Tensor, views: torch.Tensor):
    """Images (B, 1, h, w) or sequences (B, T, 1, h, w) and targets (B,) or (B, h, w) of items
    ``sample * V + k``: sample ``sample`` in view ``views[k]`` (a mirrored view swaps the mirror
    classes of ``data.mirror``: a clockwise twist becomes a counter-clockwise one)."""
    sample, view = items // len(views), views[items % len(views)]
    x, y = data.x[sample].clone(), data.y[sample].clone()
    for v in view.unique().tolist():
        sel = view == v
        x[sel] = flip_view(x[sel], v)
        y[sel] = targets_in_view(y[sel], v, data.mirror)
    return x, y


def make_loss(run: RunConfig, train: TensorData) -> nn.Module:
    """The configured loss; weighted CE takes median-frequency weights of the training targets."""
    name = run.train.loss
    weights = class_weights(train.y, run.model.num_classes) if name == "weighted_ce" else None
    loss = BothLoss(name, weights) if run.task == "both" else SegmentationLoss(name, weights)
    return loss.to(run.device)


def build(run: RunConfig, init: dict | None = None):
    """The model (seeded init; the weights of checkpoint dict ``init`` whose names and shapes
    fit), its optimizer and its step schedule."""
    torch.manual_seed(run.train.seed)
    model = create_model(run.model.arch, **run.model.kwargs())
    if init is not None:
        load_weights(model, init)
    if run.task == "classify":  # channels-last convs train ~20 % faster on CPU (oneDNN)
        model = model.to(memory_format=torch.channels_last)
    model = model.to(run.device)  # before the optimizer, whose state follows the parameters
    optimizer = make_optimizer(model, run.train)
    return model, optimizer, make_scheduler(optimizer, run.train)


def train_step(model, loss_fn, optimizer, x, y, run: RunConfig) -> float:
    """One optimisation step on images ``x`` (B, 1, h, w) and targets ``y``; returns the loss.
    ``run.precision == "bf16"`` runs the forward pass under bfloat16 autocast; the loss is taken
    on float32 logits."""
    if run.task == "classify":  # its weights are channels-last (see build)
        x = x.contiguous(memory_format=torch.channels_last)
    with torch.autocast(x.device.type, dtype=torch.bfloat16, enabled=run.precision == "bf16"):
        out = model(x)
    loss = loss_fn(tuple(o.float() for o in out) if isinstance(out, tuple) else out.float(), y)
    optimizer.zero_grad(set_to_none=True)
    loss.backward()
    optimizer.step()
    return loss.item()


@flushing()
def train_epoch(
    model, data: TensorData, loss_fn, optimizer, run: RunConfig, epoch: int, progress: bool
):
    """One epoch over a seeded permutation of (sample, view) pairs; returns the mean loss.
    Batches are drawn and flipped on the CPU, then moved to ``run.device``."""
    torch.manual_seed(epoch_seed(run.train.seed, epoch))
    views = views_of(run)
    order = torch.randperm(len(data.y) * len(views))
    model.train()
    total, size = 0.0, run.train.batch_size
    desc = f"epoch {epoch + 1}/{run.train.epochs}"
    bar = tqdm(range(0, len(order), size), desc=desc, disable=not progress, leave=False)
    for start in bar:
        x, y = get_batch(data, order[start : start + size], views)
        value = train_step(model, loss_fn, optimizer, x.to(run.device), y.to(run.device), run)
        total += value * len(y)
        bar.set_postfix(loss=f"{value:.4f}")
    return total / len(order)


def fit(
    run: RunConfig,
    data: Data,
    out_dir: str | Path | None = None,
    *,
    resume: bool = False,
    init: str | Path | dict | None = None,
    progress: bool = True,
    stop_after_epoch: int | None = None,
) -> FitResult:
    """Train ``run`` on ``data.train``, validating on ``data.val`` (if any) after every epoch.

    out_dir : run folder for ``last.pt`` (every epoch), ``best.pt`` (best val metric, or the last
    epoch without validation), ``curves.png`` and ``run.toml``; None writes nothing.
    resume : continue from ``out_dir/last.pt``. init : fine-tune from a checkpoint (a .pt path or
    its loaded dict: the weights whose names and shapes fit; ``run.train.lr_factors`` scale
    per-layer lrs). stop_after_epoch : stop once this epoch (1-based, counted from the run's
    start) is done, keeping the schedule of ``run.train.epochs``, for ``resume`` to continue.
    """
    check_precision(run.device, run.precision)
    torch.set_num_threads(run.threads)
    out = None if out_dir is None else Path(out_dir)
    resuming = resume and out is not None and (out / LAST).is_file()
    init_ckpt = load_checkpoint(init) if isinstance(init, str | Path) and not resuming else init
    init_name = init if isinstance(init, str | Path) else None if init is None else "a checkpoint"
    model, optimizer, scheduler = build(run, None if resuming else init_ckpt)
    loss_fn = make_loss(run, data.train)
    start, best, history, best_state = 0, float("nan"), [], weights_copy(model)
    if resuming:
        start, best, history, best_state, first = restore(out, run, model, optimizer, scheduler)
        init_name = first if first not in (None, "random") else init_name
    check_stop_epoch(stop_after_epoch, start, run.train.epochs, None if out is None else out / LAST)
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        write_text_atomic(out / "run.toml", to_toml(run))
    paused = False
    for epoch in range(start, run.train.epochs):
        tic = time.perf_counter()
        row = {"epoch": epoch + 1, "lr": [g["lr"] for g in optimizer.param_groups]}
        row["train_loss"] = train_epoch(model, data.train, loss_fn, optimizer, run, epoch, progress)
        if data.val is not None:
            res = evaluate_tensors(
                model, data.val, run.model.num_classes, run.eval_batch_size, loss_fn
            )
            row["val_loss"], row["val_metric"] = res.loss, res.metrics[metric_name(run.task)]
        row["seconds"] = time.perf_counter() - tic
        scheduler.step()
        history.append(row)
        saved = (optimizer, scheduler, run, data, epoch)
        if data.val is None or improved(row.get("val_metric", float("nan")), best):
            best, best_state = row.get("val_metric", best), weights_copy(model)
            save(out, BEST, model, *saved, best, history, init_name)
        save(out, LAST, model, *saved, best, history, init_name)
        if out is not None:
            best_epoch = next((h["epoch"] for h in history if h.get("val_metric") == best), None)
            title = f"{run.model.arch}, seed {run.train.seed}"
            plot_history(history, out / "curves.png", title, metric_name(run.task), best_epoch)
        if patience_out(history, run):
            break
        if stop_after_epoch is not None and epoch + 1 >= stop_after_epoch:
            paused = epoch + 1 < run.train.epochs
            break
    if data.val is not None:
        model.load_state_dict(best_state)
    return FitResult(model.to("cpu"), history, best, out, paused)
