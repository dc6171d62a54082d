"""The markdown report of ``handskin evaluate``: our rows beside the paper's Tables 3 and 8, the
scores by number of contacts where the data has several (`learn.evaluate.contacts`), the action
networks' section (`learn.evaluate.action_report`), then each model's details (training data and
start, timing, scores, confusion matrix).

    rows = [evaluate_checkpoint("runs/handsnet/best.pt", "out/forearm")]
    write_report(rows, "report.md", header="Data: out/forearm")
"""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path

import torch

from learn import metrics as M
from learn.evaluate import paper
from learn.evaluate.action_report import action_section
from learn.evaluate.contacts import contacts_section
from learn.evaluate.scoring import SEG_KEYS
from tactile.files import write_text_atomic

ARCH_LABEL = {
    "handsnet": "HandsNet",
    "vgg16": "VGG16 fine-tuned",
    "segnet": "SegNet",
    "fcn16s": "FCN",
    "vgg_svm": "VGG16 + SVM",
    "bovw": "BoVW",
    "ensemble": "Ensemble",
    "action_3d": "3D CNN",
    "compactseg": "Compact segmenter",
    "handparts": "HandParts",
}
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


def _fmt(v: float | None, scale: float = 1.0) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "unknown" if v is None else "–"
    return f"{scale * v:.2f}"


def row_labels(rows: list[dict]) -> list[str]:
    """Each row's name in the tables: the method, ", int8" as an int8 network, ", flips" with
    test-time flips; where two rows would share a name, the run folder's, then the training
    data's name after it."""
    labels = []
    for r in rows:
        name = ARCH_LABEL.get(r["arch"], r["arch"])
        if r["arch"] == "ensemble":
            name += " (" + " + ".join(ARCH_LABEL[m["arch"]] for m in r["members"]) + ")"
        labels.append(
            name + (", int8" if r.get("int8") else "") + (", flips" if r.get("tta_views") else "")
        )
    for tell in (_run_folder, _data_name):
        counts = Counter(labels)
        labels = [
            f"{b}, {tell(r)}" if counts[b] > 1 else b for b, r in zip(labels, rows, strict=True)
        ]
    return labels


def _run_folder(r: dict) -> str:
    return Path(r["checkpoint"].split(" + ")[0]).parent.name


def _data_name(r: dict) -> str:
    return Path((r.get("train_data") or {}).get("path") or "unknown data").name


def confusion_markdown(cm: torch.Tensor, names: tuple[str, ...]) -> str:
    """A markdown table of a confusion matrix as % of each true class (rows true)."""
    pct = M.percent_by_true_class(cm).numpy()
    head = "| true \\ predicted | " + " | ".join(names) + " |"
    rows = [
        f"| {n} | " + " | ".join(_fmt(float(v)) for v in row) + " |"
        for n, row in zip(names, pct, strict=True)
    ]
    return "\n".join([head, "|" + "---|" * (len(names) + 1), *rows])


def _trained_on(r: dict) -> str:
    data = r.get("train_data") or {}
    n = data.get("n_train")
    return _data_name(r) + ("" if n is None else f" ({n:,} images)")


def _table(rows: list[dict], labels: list[str], task: str) -> list[str]:
    """Table 3 (classify) or Table 8 (segment): the paper's methods, then our other rows."""
    ours = {lab: r for lab, r in zip(labels, rows, strict=True) if r["task"] == task}
    classify = task == "classify"
    table = PAPER_TABLE3 if classify else PAPER_TABLE8
    title = (
        "Hand / non-hand classification (paper: Table 3)"
        if classify
        else ("Hand-part segmentation (paper: Table 8)")
    )
    keys = ("accuracy",) if classify else SEG_KEYS
    cols = ["accuracy %"] if classify else ["Acc %", "mAcc %", "mIoU %", "fwIoU %"]
    head = [
        "method",
        *cols,
        "CPU ms/image",
        *(f"paper {c}" for c in cols),
        "paper ms",
        "trained on",
    ]
    out = [f"## {title}", "", "| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    names = list(
        dict.fromkeys(
            [n for n in table if n in ours or not any(o.startswith(n + ",") for o in ours)]
            + list(ours)
        )
    )
    for name in names:
        r, theirs = ours.get(name), table.get(name.split(",")[0], (None,) * (len(keys) + 1))
        mine = (
            ["not run"] * (len(keys) + 2)
            if r is None
            else [
                *(_fmt(r["metrics"][k], 100) for k in keys),
                _fmt(r["ms_per_image"]["fast"]),
                _trained_on(r),
            ]
        )
        cells = [name, *mine[:-1], *map(_fmt, theirs), mine[-1] if r is not None else ""]
        out.append("| " + " | ".join(cells) + " |")
    return [*out, ""]


def _hand_pixels(rows: list[dict], labels: list[str]) -> list[str]:
    """The segmenters' scores on the hand's pixels alone (`learn.metrics.without_true_class`),
    and the hand's share of the test pixels: what a whole-image Acc and fwIoU hide."""
    seg = [(lab, r) for lab, r in zip(labels, rows, strict=True) if len(r["cm"]) == 7]
    if not seg:
        return []
    share = float(
        M.without_true_class(seg[0][1]["cm"]).sum()
        / max(1, int(torch.tensor(seg[0][1]["cm"]).sum()))
    )
    out = [
        "### The same predictions on the hand's pixels",
        "",
        "Scored on the pixels the truth labels as one of the six hand parts (a hand pixel "
        f"predicted as background counts wrong). The hand's pixels are {_fmt(share, 100)} % of "
        "the test images' pixels, so a whole-image Acc is mostly background.",
        "",
        "| method | Acc % | mAcc % | mIoU % | fwIoU % |",
        "|---|---|---|---|---|",
    ]
    for lab, r in seg:
        s = M.segmentation_scores(M.without_true_class(r["cm"]))
        out.append(f"| {lab} | " + " | ".join(_fmt(s[k], 100) for k in SEG_KEYS) + " |")
    return [*out, ""]


def _timing(r: dict) -> str:
    """The sentence on CPU / GPU time per image of a report row."""
    ms, head = r["ms_per_image"], f"CPU ms/image at batch 1, {r['threads']} thread(s): "
    if r.get("timing"):  # a classical model: one path, image to label
        return head + f"{_fmt(ms['fast'])} ({r['timing']})"
    if q := r.get("int8"):
        saved = f" of {q['calibration_data']}, saved by handskin quantize" if q.get("saved") else ""
        return head + (
            f"{_fmt(ms['fast'])}, int8 ({q['backend']}; activation ranges from "
            f"{q['calibration_images']} images of the {q['calibration_split']} split{saved})"
        )
    gpu = "none (no CUDA)" if ms["gpu"] is None else _fmt(ms["gpu"])
    return head + (
        f"eval mode {_fmt(ms['eval_mode'])}, prepared (BN folded) {_fmt(ms['prepared'])}, "
        f"fast path {_fmt(ms['fast'])} (bf16 {'on' if r['bf16'] else 'off'}); GPU {gpu}"
    )


def _details(r: dict, label: str) -> list[str]:
    names = tuple(r["class_names"]) or tuple(str(i) for i in range(len(r["cm"])))
    epoch = "" if r.get("epoch") is None else f"epoch {r['epoch']}, "
    init = r.get("init")
    start = (
        ""
        if init is None
        else " Start: random (seeded)."
        if init == "random"
        else (f" Start: the weights of `{init}`.")
    )
    canvas = r.get("canvas_mm")
    size = f"input (h, w) = {tuple(r['input_size'])} px" + (
        "" if canvas is None else f" of a {canvas[0]:g} × {canvas[1]:g} mm canvas"
    )
    lines = [
        f"### {label}: `{r['checkpoint']}` ({epoch}{r['n_test']} test images)",
        "",
        f"Trained on {_trained_on(r)}.{start} {_timing(r)}; {size}.",
        "",
    ]
    for m in r.get("members") or ():
        lines.append(
            f"- member `{m['checkpoint']}`: {ARCH_LABEL.get(m['arch'], m['arch'])}, epoch "
            f"{m['epoch']}, seed {m['seed']}"
        )
    if r.get("tta_views"):
        lines += ["", f"Test-time flips: the mean softmax over views {r['tta_views']}."]
    lines += [
        "",
        "Scores (%): " + ", ".join(f"{k} {_fmt(v, 100)}" for k, v in r["metrics"].items()),
        "",
        confusion_markdown(torch.tensor(r["cm"]), names),
        "",
    ]
    if r["task"] == "segment":
        ious = M.class_ious(torch.tensor(r["cm"]))
        pairs = zip(names, ious.tolist(), strict=True)
        lines += ["IoU per class (%): " + ", ".join(f"{n} {_fmt(v, 100)}" for n, v in pairs), ""]
    return lines


def write_report(rows: list[dict], path: str | Path, header: str = "") -> Path:
    """The markdown report at ``path`` and its rows as ``.json`` beside it."""
    labels = row_labels(rows)
    path = Path(path)
    images = [(r, label) for r, label in zip(rows, labels, strict=True) if r["task"] != "action"]
    lines = ["# handskin evaluation", "", header, ""]
    if images:
        lines += [
            "Columns marked *paper* are Albini & Cannata (IJRR 2020), measured on the paper's own "
            "recordings; *unknown* marks a value we do not have. Ours are on the test split named "
            "above. Times: each inference path's median of its timed runs, the least over rounds "
            "in which a network's paths take turns.",
            "",
            *_table(rows, labels, "classify"),
            *_table(rows, labels, "segment"),
            *_hand_pixels(rows, labels),
            *contacts_section(rows, labels),
        ]
    lines += action_section(rows, labels, path)
    if images:
        lines += ["## Details", ""]
    for r, label in images:
        lines += _details(r, label)
    write_text_atomic(path, "\n".join(lines) + "\n")
    write_text_atomic(path.with_suffix(".json"), json.dumps(rows, indent=1))
    return path
