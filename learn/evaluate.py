"""Evaluation: metrics and confusion matrices of a model on tensors, the fast CPU inference
path, time per image, loss curves, and the markdown report beside the paper's Tables 3 and 8.

    res = evaluate_tensors(model, data.test, num_classes=2)   # res.metrics, res.cm, res.percent
    fast = fast_inference(model)           # BN folded, channels-last, bf16 where it is safe
    row = evaluate_checkpoint("runs/handsnet/best.pt", "out/forearm")
    write_report([row, ...], "report.md")
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from matplotlib.figure import Figure
from torch import nn

from learn import metrics as M
from learn.experiments import paper
from learn.inputs import unpressed_as_background
from learn.leakage import leakage_note
from learn.models import prepare_for_inference

CHECK_SEED = 1234  # seed of the random images used to verify the bf16 path


@dataclass
class EvalResult:
    """Confusion matrix ``cm`` (C, C) int64 (rows true), scores (fractions), mean loss, and the
    predicted classes ((S,) or (S, h, w) int64) when asked for."""

    cm: torch.Tensor
    metrics: dict[str, float]
    loss: float
    predictions: torch.Tensor | None = None

    @property
    def percent(self) -> torch.Tensor:
        """(C, C) float64: rows as percentages of the true class (the paper's tables)."""
        return M.percent_by_true_class(self.cm)


def logits_of(model: nn.Module, x: torch.Tensor, batch_size: int = 64) -> torch.Tensor:
    """Logits of ``x`` (S, 1, h, w) in eval mode under ``torch.no_grad``, batch by batch."""
    model.eval()
    with torch.no_grad():
        batches = [model(x[i : i + batch_size]).float() for i in range(0, len(x), batch_size)]
    return torch.cat(batches)


def scores(cm: torch.Tensor) -> dict[str, float]:
    """Accuracy, mean class accuracy and (for any task) Long et al.'s IoU scores, fractions."""
    return {"accuracy": M.accuracy(cm), **M.segmentation_scores(cm)}


def evaluate_tensors(
    model: nn.Module, data, num_classes: int, batch_size: int = 64,
    loss_fn: nn.Module | None = None, keep_predictions: bool = False,
) -> EvalResult:  # fmt: skip
    """Metrics of ``model`` on ``data`` (``TensorData``: x (S, 1, h, w), y (S,) or (S, h, w)).

    The model is left in eval mode. Segmentation predictions are background where the input is
    0 (`learn.inputs.unpressed_as_background`). ``loss`` is the mean of ``loss_fn`` over
    batches (NaN without a loss function); ``keep_predictions`` also returns the predictions.
    """
    cms, losses, preds = [], [], []
    for i in range(0, len(data.y), batch_size):
        x, y = data.x[i : i + batch_size], data.y[i : i + batch_size]
        out = logits_of(model, x, batch_size)
        pred = out.argmax(1) if y.ndim == 1 else unpressed_as_background(out.argmax(1), x)
        cms.append(M.confusion_matrix(y, pred, num_classes))
        if keep_predictions:
            preds.append(pred)
        if loss_fn is not None:
            with torch.no_grad():
                losses.append(float(loss_fn(out, y)) * len(y))
    cm = torch.stack(cms).sum(0)
    loss = sum(losses) / len(data.y) if losses else float("nan")
    return EvalResult(cm, scores(cm), loss, torch.cat(preds) if preds else None)


class FastInference(nn.Module):
    """A prepared model (BN folded, channels-last weights) fed channels-last input, optionally
    with its weights stored in bfloat16 (cast once, not per call as autocast would); returns
    float32 logits. Keeps the wrapped model's attributes."""

    def __init__(self, prepared: nn.Module, bf16: bool) -> None:
        super().__init__()
        self.net = copy.deepcopy(prepared).to(torch.bfloat16) if bf16 else prepared
        self.bf16 = bf16
        for name in ("num_classes", "in_channels", "task", "input_size"):
            if hasattr(prepared, name):
                setattr(self, name, getattr(prepared, name))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """``(B, C, H, W)`` → logits of the wrapped model, float32."""
        dtype = torch.bfloat16 if self.bf16 else torch.float32
        return self.net(x.to(dtype).contiguous(memory_format=torch.channels_last)).float()


def bf16_supported() -> bool:
    """True when oneDNN has native bfloat16 kernels on this CPU (AVX512-BF16 / AMX)."""
    try:
        return bool(torch.ops.mkldnn._is_mkldnn_bf16_supported())
    except (AttributeError, RuntimeError):
        return False


def agreement(a: nn.Module, b: nn.Module, x: torch.Tensor) -> float:
    """Fraction of argmax predictions (images or pixels) on which two models agree."""
    with torch.inference_mode():
        return float((a(x).argmax(1) == b(x).argmax(1)).double().mean())


def fast_inference(model: nn.Module, *, bf16: bool | None = None, check: torch.Tensor | None = None,
                   min_agreement: float = 1.0) -> nn.Module:  # fmt: skip
    """The default CPU inference path: ``prepare_for_inference`` + channels-last input + bf16.

    bf16 (default: classifiers on CPUs with native bf16) is kept only if the argmax agrees with
    the float model on ``check`` images (default: 32 seeded uniform random images) at least
    ``min_agreement`` of the time; otherwise the float path is returned.
    """
    prepared = prepare_for_inference(model)
    if bf16 is None:
        bf16 = getattr(model, "task", "") == "classification" and bf16_supported()
    float_path = FastInference(prepared, False).eval()
    if not bf16:
        return float_path
    if check is None:
        size = getattr(model, "input_size", (68, 100))
        gen = torch.Generator().manual_seed(CHECK_SEED)
        check = torch.rand(32, getattr(model, "in_channels", 1), *size, generator=gen)
    fast = FastInference(prepared, True).eval()
    return fast if agreement(fast, float_path, check) >= min_agreement else float_path


def cpu_ms_per_image(model: nn.Module, input_size: tuple[int, int], threads: int = 1,
                     n_runs: int = 100) -> float:  # fmt: skip
    """Median CPU ms per image at batch 1 after warm-up, with ``threads`` torch threads."""
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    try:
        return 1e3 * M.time_per_image(model, input_size, "cpu", n_warmup=20, n_runs=n_runs)
    finally:
        torch.set_num_threads(before)


def gpu_ms_per_image(model: nn.Module, input_size: tuple[int, int]) -> float | None:
    """Median GPU ms per image at batch 1 after warm-up, or None without CUDA."""
    if not torch.cuda.is_available():
        return None
    return 1e3 * M.time_per_image(copy.deepcopy(model), input_size, "cuda")


def plot_history(history: list[dict], path: str | Path, title: str = "",
                 metric: str = "validation metric") -> Path:  # fmt: skip
    """Loss curves (train, val) and the validation metric per epoch as a PNG (Figure API)."""
    fig = Figure(figsize=(9, 3.5), layout="constrained")
    ax_loss, ax_metric = fig.subplots(1, 2)
    epochs = [h["epoch"] for h in history]
    ax_loss.plot(epochs, [h["train_loss"] for h in history], "o-", label="train")
    if any("val_loss" in h for h in history):
        ax_loss.plot(epochs, [h.get("val_loss", math.nan) for h in history], "s-", label="val")
        ax_metric.plot(epochs, [h.get("val_metric", math.nan) for h in history], "s-", c="C1")
    ax_loss.set(xlabel="epoch", ylabel="loss", title="loss")
    ax_loss.legend()
    ax_metric.set(xlabel="epoch", ylabel="fraction", title=f"validation {metric}")
    fig.suptitle(title)
    fig.savefig(path, dpi=100)
    return Path(path)


def confusion_markdown(cm: torch.Tensor, names: tuple[str, ...]) -> str:
    """A markdown table of a confusion matrix as % of each true class (rows true)."""
    pct = M.percent_by_true_class(cm).numpy()
    head = "| true \\ predicted | " + " | ".join(names) + " |"
    rows = [f"| {n} | " + " | ".join(_pct(v) for v in row) + " |"
            for n, row in zip(names, pct, strict=True)]
    return "\n".join([head, "|" + "---|" * (len(names) + 1), *rows])


def _pct(v: float | None) -> str:
    return "–" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.2f}"


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
ARCH_LABEL = {"handsnet": "HandsNet", "vgg16": "VGG16 fine-tuned", "segnet": "SegNet",
              "fcn16s": "FCN", "vgg_svm": "VGG16 + SVM", "bovw": "BoVW"}  # fmt: skip
SEG_KEYS = ("pixel_accuracy", "mean_accuracy", "mean_iou", "fw_iou")


def evaluate_checkpoint(ckpt_path: str | Path, data_path: str | Path, *,
                        hand_classes: tuple[str, ...] | None = None, threads: int = 1,
                        time_runs: int = 100) -> dict:  # fmt: skip
    """Test-split metrics (float and fast path) and CPU ms/image (1 thread by default) of a
    checkpoint (a .pt file; a classical model.npz goes to ``learn.classical.evaluate_classical``);
    a JSON-able dict (one row of the report)."""
    from learn.breakdown import (
        accuracy_by_active_taxels,
        accuracy_by_group,
        active_taxel_counts,
        contactor_types,
    )
    from learn.checkpoint import load_checkpoint, model_from_checkpoint
    from learn.folder import is_dataset, materialize, open_split

    if Path(ckpt_path).suffix == ".npz":
        from learn.classical import evaluate_classical

        return evaluate_classical(ckpt_path, data_path, hand_classes=hand_classes,
                                  threads=threads, time_runs=time_runs)  # fmt: skip
    ckpt = load_checkpoint(ckpt_path)
    model, run = model_from_checkpoint(ckpt)
    hand = hand_classes or (ckpt.get("data") or {}).get("hand_classes")
    split = open_split(Path(data_path), "test", run.task, run.model.input_size, hand,
                       run.train.seed)  # fmt: skip
    test = materialize(split, "test")
    n_cls = run.model.num_classes
    classify_data = run.task == "classify" and is_dataset(data_path)
    ref = evaluate_tensors(model, test, n_cls, keep_predictions=classify_data)
    by_size = by_contactor = None
    if classify_data:  # accuracy by contact size and by contactor
        pred = ref.predictions.numpy()
        names = list(ckpt.get("class_names") or [str(c) for c in range(n_cls)])
        by_size = accuracy_by_active_taxels(pred, test.y.numpy(),
                                            active_taxel_counts(data_path, split.indices), names)
        by_contactor = accuracy_by_group(pred, test.y.numpy(),
                                         contactor_types(data_path, split.indices))
    fast = fast_inference(model, check=test.x[:64])
    res = evaluate_tensors(fast, test, n_cls)
    if abs(res.metrics["accuracy"] - ref.metrics["accuracy"]) > 0.005:  # keep predictions
        fast = fast_inference(model, bf16=False)
        res = evaluate_tensors(fast, test, n_cls)
    size = run.model.input_size
    ms = {"eval_mode": cpu_ms_per_image(model, size, threads, time_runs),
          "prepared": cpu_ms_per_image(prepare_for_inference(model), size, threads, time_runs),
          "fast": cpu_ms_per_image(fast, size, threads, time_runs),
          "gpu": gpu_ms_per_image(model, size)}  # fmt: skip
    return {"checkpoint": str(ckpt_path), "arch": run.model.arch, "task": run.task,
            "epoch": ckpt["epoch"], "class_names": list(ckpt.get("class_names", [])),
            "n_test": len(test.y), "cm": ref.cm.tolist(), "metrics": ref.metrics,
            "fast_metrics": res.metrics, "bf16": bool(getattr(fast, "bf16", False)),
            "ms_per_image": ms, "threads": threads, "seed": ckpt.get("seed"),
            "config": ckpt["config"], "input_size": list(size),
            "train_versions": ckpt.get("versions"), "train_data": ckpt.get("data"),
            "init": ckpt.get("init"),
            "shared_with_training": shared_with_training(ckpt.get("data"), data_path),
            "by_active_taxels": by_size, "by_contactor": by_contactor}  # fmt: skip


def _fmt(v: float | None, scale: float = 1.0) -> str:
    return "unknown" if v is None else f"{scale * v:.2f}"


def shared_with_training(train_data: dict | None, data_path: str | Path) -> dict | None:
    """``learn.leakage.shared_groups`` of a model's training data (its checkpoint's ``data``
    record) and the data it is scored on; None when unknown or impossible."""
    from learn.leakage import shared_groups

    path = (train_data or {}).get("path")
    return None if not path else shared_groups(path, data_path)


def _data_name(r: dict) -> str:
    """A report row's training data: ``name (N train)``, "unknown" if the checkpoint does not
    say."""
    d = r.get("train_data") or {}
    if not d.get("path"):
        return "unknown"
    n = d.get("n_train")
    return Path(str(d["path"])).name + ("" if n is None else f" ({n:,} train)")


def trained_on(r: dict) -> str:
    """The "trained on" cell of a report row: its training data, and a warning when test
    samples share subjects or object instances with it (``learn.leakage``)."""
    leak = (r.get("shared_with_training") or {}).get("test_samples")
    return _data_name(r) + (f"; not held out: {leak} test samples share its subjects"
                            if leak else "")  # fmt: skip


def _init_text(r: dict) -> str:
    """The report's sentence on where a network's training started (checkpoints record it)."""
    if r.get("timing"):  # classical: no network trained here, or described in its config
        return ""
    init = r.get("init")
    if init is None:
        return " Initialisation: not recorded (a checkpoint from before it was)."
    return (" Initialisation: random (seeded)." if init == "random"
            else f" Initialisation: the weights of `{init}`.")  # fmt: skip


def row_labels(rows: list[dict]) -> list[str]:
    """Table labels of report rows: the method's name (``ARCH_LABEL``), with the training data
    and then the run folder added where two rows would otherwise share a label."""
    labels = [ARCH_LABEL.get(r["arch"], r["arch"]) for r in rows]
    for extra in (_data_name, lambda r: Path(r["checkpoint"]).parent.name):
        dup = {lab for lab in labels if labels.count(lab) > 1}
        labels = [f"{lab}, {extra(r)}" if lab in dup else lab
                  for lab, r in zip(labels, rows, strict=True)]  # fmt: skip
    return labels


def _ours(rows: list[dict], task: str) -> dict[str, dict]:
    return {lab: r for lab, r in zip(row_labels(rows), rows, strict=True) if r["task"] == task}


def _paper_row(name: str, table: dict, n: int) -> tuple:
    """The paper's values for a label (its method name before any ", ..." suffix)."""
    return table.get(name.split(",")[0], (None,) * n)


def _shown_longer(name: str, ours: dict[str, dict]) -> bool:
    """True when a paper method has no row of its own but rows under longer labels."""
    return name not in ours and any(o.startswith(name + ",") for o in ours)


def _table3(rows: list[dict]) -> list[str]:
    ours = _ours(rows, "classify")
    out = ["## Hand / non-hand classification (paper: Table 3)", "",
           "| method | accuracy % (ours) | CPU ms/image (ours, batch 1) | accuracy % (paper) "
           "| ms/image (paper) | trained on |", "|---|---|---|---|---|---|"]  # fmt: skip
    for name in dict.fromkeys([*PAPER_TABLE3, *ours]):
        if _shown_longer(name, ours):
            continue
        r, (p_acc, p_ms) = ours.get(name), _paper_row(name, PAPER_TABLE3, 2)
        acc = "not run" if r is None else _fmt(r["metrics"]["accuracy"], 100)
        ms = "not run" if r is None else _fmt(r["ms_per_image"]["fast"])
        where = "" if r is None else trained_on(r)
        out.append(f"| {name} | {acc} | {ms} | {_fmt(p_acc)} | {_fmt(p_ms)} | {where} |")
    return out


def _table8(rows: list[dict]) -> list[str]:
    ours = _ours(rows, "segment")
    out = ["## Hand-part segmentation (paper: Table 8)", "",
           "| method | Acc % | mAcc % | mIoU % | fwIoU % | CPU ms/image (fast path) "
           "| paper Acc % | paper mAcc % | paper mIoU % | paper fwIoU % | paper ms/image "
           "| trained on |", "|---|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip
    for name in dict.fromkeys([*PAPER_TABLE8, *ours]):
        if _shown_longer(name, ours):
            continue
        r, paper = ours.get(name), _paper_row(name, PAPER_TABLE8, 5)
        mine = ["not run"] * 5 if r is None else [
            *(_fmt(r["metrics"][k], 100) for k in SEG_KEYS), _fmt(r["ms_per_image"]["fast"])]
        where = "" if r is None else trained_on(r)
        out.append(f"| {name} | " + " | ".join([*mine, *map(_fmt, paper), where]) + " |")
    return out


def _timing(r: dict) -> str:
    """The sentence on CPU / GPU time per image of a report row."""
    ms, head = r["ms_per_image"], f"CPU ms/image at batch 1, {r['threads']} thread(s): "
    if r.get("timing"):  # a classical model: one path, image to label
        return head + f"{_fmt(ms['fast'])} ({r['timing']})"
    gpu = "none (no CUDA)" if ms["gpu"] is None else _fmt(ms["gpu"])
    return (head + f"eval mode {_fmt(ms['eval_mode'])}, prepared (BN folded) "
            f"{_fmt(ms['prepared'])}, fast path {_fmt(ms['fast'])} "
            f"(bf16 {'on' if r['bf16'] else 'off'}); GPU {gpu}")  # fmt: skip


def _details(r: dict, label: str) -> list[str]:
    names = tuple(r["class_names"]) or tuple(str(i) for i in range(len(r["cm"])))
    epoch = "" if r["epoch"] is None else f"epoch {r['epoch']}, "
    size = r.get("input_size") or r["config"]["model"]["input_size"]
    return [f"### {label} — `{r['checkpoint']}` "
            f"({epoch}seed {r['seed']}, {r['n_test']} test images)", "",
            f"Trained on: {trained_on(r)}.{_init_text(r)}", "",
            *([note, ""] if (note := leakage_note(r.get("shared_with_training"))) else []),
            f"{_timing(r)}; input (h, w) = {tuple(size)} px.", "",
            "Scores (%): " + ", ".join(f"{k} {_fmt(v, 100)}" for k, v in r["metrics"].items()),
            "", "Confusion matrix, % of each true class:", "",
            confusion_markdown(torch.tensor(r["cm"]), names), "",
            *_by_size(r), *_merged(r)]  # fmt: skip


#: Class groups of the 7-class hand-part segmentation the report also scores, (title, groups).
MERGED_VIEWS = (
    ("hand against background", [[0], [1, 2, 3, 4, 5, 6]]),
    ("fingers as one class", [[0], [1, 2, 3, 4, 5], [6]]),
    ("mirror pairs merged (index + pinkie, middle + ring)", [[0], [1], [2, 5], [3, 4], [6]]),
)


def _merged(r: dict) -> list[str]:
    """Per-class IoU and the mIoU of coarser class groupings, of a 7-class segmenter row: how
    much of the error is finger identity rather than finding the hand."""
    if r["task"] != "segment" or len(r["cm"]) != 7:
        return []
    names = tuple(r["class_names"]) or tuple(str(i) for i in range(7))
    ious = M.class_ious(torch.tensor(r["cm"]))
    lines = ["IoU per class (%): " + ", ".join(
        f"{n} {_fmt(float(v), 100)}" for n, v in zip(names, ious, strict=True)), "",
        "mIoU (%) of coarser groupings of the same predictions:", ""]  # fmt: skip
    for title, groups in MERGED_VIEWS:
        lines.append(f"- {title}: {_fmt(M.mean_iou(M.merge_classes(r['cm'], groups)), 100)}")
    return [*lines, ""]


def _by_size(r: dict) -> list[str]:
    """The accuracy-by-contact-size table of a classifier row on a handskin dataset."""
    from learn.breakdown import breakdown_markdown, group_markdown

    if not r.get("by_active_taxels"):
        return []
    out = ["Accuracy by contact size (active taxels: pressure above the dataset's active "
           "threshold):", "", *breakdown_markdown(r["by_active_taxels"]), ""]
    if r.get("by_contactor"):
        out += ["Accuracy by contactor (the dataset's `contactor` kind and type), least accurate "
                "first:", "", *group_markdown(r["by_contactor"]), ""]
    return out


def write_report(rows: list[dict], path: str | Path, header: str = "") -> Path:
    """The markdown report: our rows next to the paper's Tables 3 and 8 ("paper" columns;
    "unknown" where we do not know the paper's value), then per-model details."""
    lines = ["# handskin evaluation", "", header, "",
             "Columns marked *paper* are Albini & Cannata (IJRR 2020); ours are on the test split "
             "named above. Timing: median of 100 runs after 20 warm-up runs.", "",
             *_table3(rows), "", *_table8(rows), "", "## Details", ""]  # fmt: skip
    for r, label in zip(rows, row_labels(rows), strict=True):
        lines += _details(r, label)
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return Path(path)
