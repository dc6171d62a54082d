"""Evaluation: metrics and confusion matrices of a model on tensors, and a checkpoint's row of
the report (``learn.eval_report`` writes it beside the paper's Tables 3 and 8); the fast
inference path and the timing are ``learn.fastpath``, the training curves ``learn.curves``.

    res = evaluate_tensors(model, data.test, num_classes=2)   # res.metrics, res.cm, res.percent
    row = evaluate_checkpoint("runs/handsnet/best.pt", "out/forearm")
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import torch
from torch import nn

from learn import metrics as M
from learn.compiled import CompileUnavailable, compile_at, compiled_agreement
from learn.device import device_of
from learn.experiments import paper
from learn.fastpath import check_timing, fast_inference, gpu_ms_per_image, interleaved_cpu_ms
from learn.inputs import unpressed_as_background
from learn.models import prepare_for_inference
from learn.numerics import flushing
from learn.tta import FlipTTA
from tactile.dataset.reader import DATASET
from tactile.errors import ConfigError

if TYPE_CHECKING:
    from torch.utils.data import Dataset

    from learn.folder import TensorData
    from learn.run_config import RunConfig


@dataclass
class EvalResult:
    """Confusion matrix ``cm`` (C, C) int64 (rows true), scores (fractions), mean loss, and the
    predicted classes ((S,) or (S, h, w) int64) and, for a classifier, the softmax probability
    of each predicted class ((S,) float32) when asked for."""

    cm: torch.Tensor
    metrics: dict[str, float]
    loss: float
    predictions: torch.Tensor | None = None
    confidence: torch.Tensor | None = None

    @property
    def percent(self) -> torch.Tensor:
        """(C, C) float64: rows as percentages of the true class (the paper's tables)."""
        return M.percent_by_true_class(self.cm)


def logits_of(model: nn.Module, x: torch.Tensor, batch_size: int = 64) -> torch.Tensor:
    """Float32 logits, on the CPU, of ``x`` (S, 1, h, w) in eval mode under ``torch.no_grad``,
    batch by batch on the model's device (a GPU during a run with ``RunConfig.device``)."""
    model.eval()
    dev = device_of(model)
    with torch.no_grad():
        batches = [
            model(x[i : i + batch_size].to(dev)).float().cpu() for i in range(0, len(x), batch_size)
        ]
    return torch.cat(batches)


def scores(cm: torch.Tensor) -> dict[str, float]:
    """Accuracy, mean class accuracy and (for any task) Long et al.'s IoU scores, fractions."""
    return {"accuracy": M.accuracy(cm), **M.segmentation_scores(cm)}


@flushing()
def evaluate_tensors(
    model: nn.Module,
    data,
    num_classes: int,
    batch_size: int = 64,
    loss_fn: nn.Module | None = None,
    keep_predictions: bool = False,
) -> EvalResult:
    """Metrics of ``model`` on ``data`` (``TensorData``: x (S, 1, h, w), y (S,) or (S, h, w)).

    The model is left in eval mode. Segmentation predictions are background where the input is
    0 (`learn.inputs.unpressed_as_background`). ``loss`` is the mean of ``loss_fn`` over
    batches (NaN without a loss function); ``keep_predictions`` also returns the predictions.
    """
    cms, losses, preds, conf = [], [], [], []
    loss_dev = None if loss_fn is None else device_of(loss_fn)  # where its class weights live
    for i in range(0, len(data.y), batch_size):
        x, y = data.x[i : i + batch_size], data.y[i : i + batch_size]
        out = logits_of(model, x, batch_size)
        pred = out.argmax(1) if y.ndim == 1 else unpressed_as_background(out.argmax(1), x)
        cms.append(M.confusion_matrix(y, pred, num_classes))
        if keep_predictions:
            preds.append(pred)
            conf += [out.softmax(1).amax(1)] if y.ndim == 1 else []
        if loss_fn is not None:
            with torch.no_grad():
                losses.append(float(loss_fn(out.to(loss_dev), y.to(loss_dev))) * len(y))
    cm = torch.stack(cms).sum(0)
    loss = sum(losses) / len(data.y) if losses else float("nan")
    return EvalResult(
        cm, scores(cm), loss, torch.cat(preds) if preds else None, torch.cat(conf) if conf else None
    )


def scored_fast_path(
    make: Callable[..., nn.Module],
    test: TensorData,
    num_classes: int,
    ref_accuracy: float | None = None,
) -> tuple[nn.Module, EvalResult]:
    """The fast inference path and its test result. ``make(**kw)`` builds it with
    `learn.fastpath.fast_inference`'s keywords: first bf16 where the CPU has it and its argmax
    agrees on 64 test images (``check``); if its (pixel) accuracy then strays more than 0.5 points
    from ``ref_accuracy`` (eval mode's; None skips the check), fp32, so the fast path keeps eval
    mode's predictions."""
    fast = make(check=test.x[:64])
    res = evaluate_tensors(fast, test, num_classes)
    if ref_accuracy is not None and abs(res.metrics["accuracy"] - ref_accuracy) > 0.005:
        fast = make(bf16=False)
        res = evaluate_tensors(fast, test, num_classes)
    return fast, res


def metrics_from_cm(cm: np.ndarray | torch.Tensor) -> dict[str, float]:
    """The report's scores from a confusion matrix (fractions)."""
    return scores(torch.as_tensor(np.asarray(cm)))


# --- checkpoints on a test split, and the report -------------------------------------------

#: The paper's Table 3 (hand / non-hand, % accuracy; ms per image). None: not known to us.
PAPER_TABLE3 = {
    "HandsNet": (paper.HANDSNET_ACCURACY_PCT, paper.HANDSNET_MS_PER_IMAGE),
    "VGG16 + SVM": (None, None),
    "VGG16 fine-tuned": (None, None),
    "BoVW": (None, None),
}
#: The paper's Table 8 (segmentation, %: Acc, mAcc, mIoU, fwIoU; ms per image). None: unknown.
PAPER_TABLE8 = {
    "SegNet": (paper.SEGNET_ACC_PCT, None, paper.SEGNET_MIOU_PCT, None, paper.SEGNET_MS_PER_IMAGE),
    "FCN": (None, None, None, None, None),
}
ARCH_LABEL = {
    "handsnet": "HandsNet",
    "vgg16": "VGG16 fine-tuned",
    "segnet": "SegNet",
    "fcn16s": "FCN",
    "vgg_svm": "VGG16 + SVM",
    "bovw": "BoVW",
}
SEG_KEYS = ("pixel_accuracy", "mean_accuracy", "mean_iou", "fw_iou")


def evaluate_checkpoint(
    ckpt_path: str | Path,
    data_path: str | Path,
    *,
    hand_classes: tuple[str, ...] | None = None,
    threads: int = 1,
    time_runs: int = 100,
    tta: bool = False,
    int8: bool = False,
    compiled: bool = False,
    time_rounds: int = 3,
) -> dict:
    """Test-split metrics (float and fast path) and CPU ms/image (1 thread by default) of a
    checkpoint (a .pt file; a classical model.npz goes to ``learn.classical.evaluate_classical``);
    a JSON-able dict (one row of the report). ``tta``: every path, timing included, runs with
    test-time flips over the views the network was trained on (`learn.tta.FlipTTA`). ``int8``
    (HandsNet only): scores, breakdowns and timing are of its int8 copy (`learn.quantize`),
    calibrated on training images of ``data_path``; an int8 file (``handskin quantize``,
    `learn.int8_file`) is scored as its saved int8 network, ``int8`` or not. ``compiled``: also
    time the float fast path compiled by TorchInductor (`learn.compiled`; ``ms_per_image``'s
    ``"compiled"``, None when not asked, for int8, or when compiling fails, then
    ``compile_note`` says why; ``compiled_agreement``: the fraction of 64 test images, or of
    their pixels, on which its argmax equals the float fast path's). Timing: each path's
    median of ``time_runs`` runs at batch 1, the least over ``time_rounds`` rounds in which the
    paths take turns (`learn.fastpath.interleaved_cpu_ms`)."""
    from learn.checkpoint import load_checkpoint, model_from_checkpoint
    from learn.ensemble import Member

    check_timing(time_runs, time_rounds, threads)

    if Path(ckpt_path).suffix == ".npz":
        from learn.classical import evaluate_classical

        return evaluate_classical(
            ckpt_path,
            data_path,
            hand_classes=hand_classes,
            threads=threads,
            time_runs=time_runs,
            time_rounds=time_rounds,
        )
    from learn.int8_file import is_int8

    ckpt = load_checkpoint(ckpt_path)
    model, run = model_from_checkpoint(ckpt, int8_ok=True)
    return _evaluate_members(
        [Member(Path(ckpt_path), ckpt, model, run)],
        data_path,
        hand_classes,
        threads,
        time_runs,
        tta,
        int8 or is_int8(ckpt),
        compiled,
        time_rounds,
    )


def evaluate_ensemble(
    ckpt_paths: list[str | Path],
    data_path: str | Path,
    *,
    hand_classes: tuple[str, ...] | None = None,
    threads: int = 1,
    time_runs: int = 100,
    tta: bool = False,
    compiled: bool = False,
    time_rounds: int = 3,
) -> dict:
    """`evaluate_checkpoint` of the mean softmax of two or more networks of one task
    (`learn.ensemble.MeanSoftmax`; with ``tta``, each member with its own test-time flips).
    The row's ``arch`` is ``"ensemble"``; ``members`` lists each network's checkpoint, arch,
    width, epoch, seed, training data and views."""
    from learn.ensemble import load_members

    check_timing(time_runs, time_rounds, threads)
    return _evaluate_members(
        load_members(ckpt_paths),
        data_path,
        hand_classes,
        threads,
        time_runs,
        tta,
        compiled=compiled,
        time_rounds=time_rounds,
    )


def _evaluate_members(
    members: list,
    data_path: str | Path,
    hand_classes: tuple[str, ...] | None,
    threads: int,
    time_runs: int,
    tta: bool,
    int8: bool = False,
    compiled: bool = False,
    time_rounds: int = 3,
) -> dict:
    """The report row of one network or the mean of several (`learn.ensemble.Member` list);
    ``int8``: of one HandsNet's int8 copy; ``compiled``: also timed compiled."""
    from learn.breakdown import (
        action_names,
        classifier_breakdown,
        parts_in_contact,
        segmenter_breakdown,
    )
    from learn.cluster_bootstrap import grouped_mean_iou_interval, sample_groups
    from learn.ensemble import MeanSoftmax
    from learn.folder import group_ids, is_dataset
    from learn.significance import mean_iou_interval, per_image_confusion
    from learn.worst import N_WORST_KEPT, N_WORST_MAPS, pack_labels, worst_segmentations

    first, run = members[0], members[0].run
    views = [tta_views(m.run, m.path) for m in members] if tta else None

    def build(path_of) -> nn.Module:  # one inference path of every member, flipped, averaged
        nets = [path_of(m.model) for m in members]
        nets = [FlipTTA(n, v) for n, v in zip(nets, views, strict=True)] if tta else nets
        return nets[0] if len(nets) == 1 else MeanSoftmax(nets)

    ckpt = first.ckpt
    hand = hand_classes or (ckpt.get("data") or {}).get("hand_classes")
    split, test = read_test_split(Path(data_path), run, hand)
    n_cls = run.model.num_classes
    on_dataset = is_dataset(data_path)
    classify_data = run.task == "classify" and on_dataset
    scored = np.asarray(split.indices, dtype=np.int64) if on_dataset else None  # dataset indices
    if int8:  # a ConfigError for another network; calibrated on training images, not test
        from learn.quantize import int8_with_note

        q8, int8_note = int8_with_note(first.model, run, ckpt, Path(data_path), hand)
    model = build((lambda m: q8) if int8 else (lambda m: m))
    ref = evaluate_tensors(model, test, n_cls, keep_predictions=on_dataset)
    seg_groups = worst = miou_interval = groups = None
    if on_dataset:  # each test sample's subject / object instance, for intervals over them
        groups = sample_groups(*group_ids(split)[1:], n=len(test.y))
    found = dict.fromkeys(
        (
            "by_active_taxels",
            "by_force",
            "by_contactor",
            "hands_by_parts",
            "hands_by_action",
            "errors",
        )
    )
    if classify_data:  # accuracy by contact size and by contactor, most confident errors
        names = list(ckpt.get("class_names") or [str(c) for c in range(n_cls)])
        found = classifier_breakdown(
            data_path,
            split.indices,
            ref.predictions.numpy(),
            test.y.numpy(),
            ref.confidence.numpy(),
            names,
        )
    elif on_dataset:  # segmentation scores by contactor, action and hand parts touching
        pred, y = ref.predictions.numpy(), test.y.numpy()
        parts = [str(k) for k in parts_in_contact(y, n_cls)]
        actions = action_names(data_path, split.indices)
        seg_groups = segmenter_breakdown(data_path, split.indices, pred, y, n_cls, actions, parts)
        cms = per_image_confusion(pred, y, n_cls)
        worst, order = worst_segmentations(
            pred, y, split.indices, n_cls, {"action": actions, "hand parts touching": parts}, cms
        )
        worst = {"images": worst[:N_WORST_KEPT], "maps": pack_labels(pred[order[:N_WORST_MAPS]])}
        miou_interval = [*mean_iou_interval(cms), *grouped_mean_iou_interval(cms, groups)]
    size = run.model.input_size
    compile_note = agree = compiled_net = None
    if int8:  # one path: the int8 network is its own fast path
        fast, res = model, ref
        (t,) = interleaved_cpu_ms([model], size, threads, time_runs, time_rounds)
        ms = {"eval_mode": t, "prepared": t, "fast": t, "compiled": None, "gpu": None}
    else:
        fast, res = scored_fast_path(
            lambda **kw: build(lambda m: fast_inference(m, **kw)),
            test,
            n_cls,
            ref.metrics["accuracy"],
        )
        if compiled:  # at batch 1; its argmax checked on 64 test images, one at a time
            float_path = build(lambda m: fast_inference(m, bf16=False))
            try:
                compiled_net = compile_at(float_path, size, threads)
                agree = compiled_agreement(compiled_net, float_path, test.x[:64])
            except CompileUnavailable as err:
                compile_note = str(err)
        paths = [model, build(prepare_for_inference), fast, compiled_net]
        times = interleaved_cpu_ms(paths, size, threads, time_runs, time_rounds)  # paths in turn
        ms = {
            **dict(zip(("eval_mode", "prepared", "fast", "compiled"), times, strict=True)),
            "gpu": gpu_ms_per_image(model, size),
        }
        if compiled_net is not None:
            torch.compiler.reset()  # drop the compiled code and its frozen weights
    row = {
        "checkpoint": str(first.path),
        "arch": run.model.arch,
        "task": run.task,
        "epoch": ckpt["epoch"],
        "class_names": list(ckpt.get("class_names", [])),
        "n_test": len(test.y),
        "cm": ref.cm.tolist(),
        "metrics": ref.metrics,
        "fast_metrics": res.metrics,
        "bf16": bool(getattr(fast, "bf16", False)),
        "ms_per_image": ms,
        "compiled_agreement": agree,
        "compile_note": compile_note,
        "threads": threads,
        "time_runs": time_runs,
        "time_rounds": time_rounds,
        "seed": ckpt.get("seed"),
        "config": ckpt["config"],
        "input_size": list(size),
        "canvas_mm": run.model.canvas_mm and list(run.model.canvas_mm),
        "train_versions": ckpt.get("versions"),
        "train_data": ckpt.get("data"),
        "test_data": str(data_path),
        "init": ckpt.get("init"),
        "shared_with_training": shared_with_training(ckpt, data_path, scored),
        **found,
        "segmentation_by_group": seg_groups,
        "worst": worst,
        "mean_iou_interval": miou_interval and miou_interval[:2],
        "mean_iou_interval_groups": miou_interval and miou_interval[2:],
        "per_image_cm": None if miou_interval is None else cms.astype(np.int64).tolist(),
        "test_indices": None if groups is None else [int(i) for i in split.indices],
        "test_groups": None if groups is None else groups.tolist(),
        "tta_views": views and views[0],
        "int8": int8_note if int8 else None,
    }
    return (
        row if len(members) == 1 else {**row, **_ensemble_fields(members, views, data_path, scored)}
    )


def read_test_split(
    data_path: Path, run: RunConfig, hand_classes: tuple[str, ...] | None
) -> tuple[Dataset, TensorData]:
    """(un-flipped test ``Dataset``, its ``TensorData`` in memory) of ``data_path`` as ``run``
    (a ``RunConfig``) reads it. The last one read is kept, so the rows of one ``handskin
    evaluate`` that share task, input size, canvas (and, for an image folder, hand classes and
    seed) read the split once; the key holds the files' size and modification time, so data
    rewritten in between is read afresh."""
    from learn.folder import is_dataset, materialize, open_split

    on_dataset = is_dataset(data_path)
    stamp = tuple((str(f), f.stat().st_mtime_ns, f.stat().st_size) for f in _data_files(data_path))
    folder_only = None if on_dataset else (hand_classes and tuple(hand_classes), run.train.seed)
    key = (
        str(Path(data_path).resolve()),
        stamp,
        run.task,
        tuple(run.model.input_size),
        run.model.canvas_mm and tuple(run.model.canvas_mm),
        folder_only,
    )
    if _TEST_SPLIT.get("key") != key:
        _TEST_SPLIT.clear()  # free the last split before reading the next
        split = open_split(
            data_path,
            "test",
            run.task,
            run.model.input_size,
            hand_classes,
            run.train.seed,
            run.model.canvas_mm,
        )
        _TEST_SPLIT.update(key=key, value=(split, materialize(split, "test")))
    return _TEST_SPLIT["value"]


_TEST_SPLIT: dict = {}  # key, (split, tensors) of the last test split read


def _data_files(path: Path) -> list[Path]:
    """The files whose change means new data: a dataset's .h5 and the files beside it, or an
    image folder's files."""
    path = Path(path)
    if path.is_file():
        return [path]
    files = path.iterdir() if (path / DATASET).is_file() else path.rglob("*")
    return sorted(f for f in files if f.is_file())


def _ensemble_fields(
    members: list, views: list | None, data_path: str | Path, scored: np.ndarray | None = None
) -> dict:
    """The fields of an ensemble's row that differ from a single network's: per-member
    records, no single epoch, seed or config; training data and leakage pooled."""
    datas = [m.ckpt.get("data") or {} for m in members]
    same_data = all(d.get("path") == datas[0].get("path") for d in datas)
    return {
        "checkpoint": " + ".join(str(m.path) for m in members),
        "arch": "ensemble",
        "epoch": None,
        "seed": None,
        "config": None,
        "init": None,
        "train_data": datas[0] if same_data else None,
        "shared_with_training": shared_with_training([m.ckpt for m in members], data_path, scored),
        "tta_views": sorted({v for vs in views for v in vs}) if views else None,
        "members": [
            {
                "checkpoint": str(m.path),
                "arch": m.run.model.arch,
                "width": m.ckpt["config"]["model"].get("width"),
                "epoch": m.ckpt["epoch"],
                "seed": m.ckpt.get("seed"),
                "train_data": d,
                "init": m.ckpt.get("init"),
                "tta_views": views[k] if views else None,
            }
            for k, (m, d) in enumerate(zip(members, datas, strict=True))
        ],
    }


def tta_views(run, ckpt_path: str | Path) -> list[int]:
    """The view ids (``learn.tta.VIEW_DIMS``) a network was trained on (``run``, its RunConfig),
    for test-time flips; a ConfigError when it was trained on the original view only."""
    from learn.train import views_of

    views = views_of(run).tolist()
    if len(views) < 2:
        raise ConfigError(
            f"{ckpt_path} was trained without flips (flips = false), so test-time "
            "flips would show it views it never saw. Fix: evaluate it without "
            "--tta, or train with flips = true"
        )
    return views


def shared_with_training(
    models: Mapping | Sequence[Mapping] | None,
    data_path: str | Path,
    among: np.ndarray | None = None,
) -> dict | None:
    """``learn.leakage.shared_groups`` of the data a model learned from (its checkpoint dict or
    classical model ``meta``: its ``data`` and ``ancestry``, `learn.leakage.lineage`; pooled over
    an ensemble's list of them) and the data it is scored on (``among``: the dataset indices of
    the samples scored; default its test split), its own split checked too when it learned from
    ``data_path`` itself; None when unknown or impossible."""
    from learn.leakage import lineage, shared_groups

    many = [models] if models is None or isinstance(models, Mapping) else list(models)
    paths = [r["path"] for m in many for r in lineage(m)]
    return shared_groups(paths, data_path, among, own_split=True) if paths else None
