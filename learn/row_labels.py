"""Labels of `handskin evaluate` report rows: a method's name, and what tells two rows of one
method apart (input size, width, initialisation, epochs, training precision, views and shifts,
weight averaging, seed, training data, run folder).
Used by the report's tables (`learn.eval_report`) and by the charts drawn from report JSON."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from learn.config import ModelConfig
from learn.evaluate import ARCH_LABEL


def data_name(r: dict) -> str:
    """A report row's training data: ``name (N train)``, "unknown" if the checkpoint does not
    say; an ensemble's, its members' (one folder with several counts: ``name (N-M train)``, as
    seeds split validation off differently)."""
    if r.get("members"):
        return _members_data(r["members"])
    d = r.get("train_data") or {}
    if not d.get("path"):
        return "unknown"
    n = d.get("n_train")
    return Path(str(d["path"])).name + ("" if n is None else f" ({n:,} train)")


def _members_data(members: list[dict]) -> str:
    names = list(dict.fromkeys(data_name({"train_data": m.get("train_data")}) for m in members))
    datas = [m.get("train_data") or {} for m in members]
    folders = {Path(str(d.get("path"))).name for d in datas}
    counts = [d.get("n_train") for d in datas]
    if len(names) == 1 or len(folders) > 1 or None in counts or not datas[0].get("path"):
        return " + ".join(names)
    return f"{folders.pop()} ({min(counts):,}-{max(counts):,} train)"


#: Label suffix of a row scored with test-time flips (``learn.tta``).
TTA_SUFFIX = " + test-time flips"
#: Label suffix of a row scored as an int8 network (``learn.quantize``).
INT8_SUFFIX = " int8"


def row_labels(rows: list[dict]) -> list[str]:
    """Table labels of report rows: the method's name (``ARCH_LABEL``, then `INT8_SUFFIX` for an
    int8 network and `TTA_SUFFIX` for test-time flips); where two rows would share a label, the
    input size, then the width multiplier, HandsNet's dropout, the initialisation, the training
    epochs, the optimizer and weight decay, the training precision, the training views (and
    mixup), the weight averaging, the label smoothing, the contactor-type head, the teacher, the
    seed (each when theirs differ), then the training data, then the run folder, then the
    file's name (``best.pt``, ``best_int8.pt``, ...; when theirs differ), added. Labels are
    unique: rows still alike are numbered (``#2``, ...), so a report never merges two of them."""
    labels = [
        method_label(r)
        + (INT8_SUFFIX if r.get("int8") else "")
        + (TTA_SUFFIX if r.get("tta_views") else "")
        for r in rows
    ]
    for extra, only_if_differs in (
        (size_label, True),
        (lambda r: width_label(r) or "default width", True),
        (dropout_label, True),
        (init_label, True),
        (epochs_label, True),
        (optimizer_label, True),
        (precision_label, True),
        (views_label, True),
        (averaging_label, True),
        (smoothing_label, True),
        (types_label, True),
        (teacher_label, True),
        (lambda r: f"seed {r.get('seed')}", True),
        (data_name, False),
        (lambda r: Path(r["checkpoint"]).parent.name, False),
        (lambda r: Path(r["checkpoint"]).name, True),
    ):
        groups: dict[str, set[str]] = {}
        for lab, r in zip(labels, rows, strict=True):
            groups.setdefault(lab, set()).add(extra(r))
        dup = {
            lab
            for lab in labels
            if labels.count(lab) > 1 and (len(groups[lab]) > 1 or not only_if_differs)
        }
        labels = [
            f"{lab}, {extra(r)}" if lab in dup else lab for lab, r in zip(labels, rows, strict=True)
        ]
    seen: Counter[str] = Counter()
    for i, lab in enumerate(labels):
        seen[lab] += 1
        labels[i] = lab if seen[lab] == 1 else f"{lab} #{seen[lab]}"
    return labels


def method_label(r: dict) -> str:
    """A row's method: ``ARCH_LABEL`` of its arch; for an ensemble ``mean of A + B``, a repeated
    method counted (``mean of 2 x SegNet``), and, when every member is one method, their seeds
    if those differ (``mean of 3 x HandsNet (seeds 0, 1, 2)``)."""
    members = r.get("members")
    if not members:
        return ARCH_LABEL.get(r["arch"], r["arch"])
    names = [ARCH_LABEL.get(m["arch"], m["arch"]) for m in members]
    counts = Counter(names)  # first-seen order
    label = "mean of " + " + ".join(n if k == 1 else f"{k} x {n}" for n, k in counts.items())
    seeds = [m.get("seed") for m in members]
    if len(counts) == 1 and len(set(seeds)) > 1:
        label += " (seeds " + ", ".join(str(s) for s in seeds) + ")"
    return label


def size_label(r: dict) -> str:
    """``<h> x <w> px``, a report row's network input size, then `` on a <H> x <W> mm canvas``
    when its images are centred on one (``ModelConfig.canvas_mm``)."""
    model = (r.get("config") or {}).get("model") or {}
    h, w = r.get("input_size") or model.get("input_size") or ModelConfig().input_size
    canvas = r.get("canvas_mm") or model.get("canvas_mm")
    return f"{h} x {w} px" + (f" on a {canvas[0]:g} x {canvas[1]:g} mm canvas" if canvas else "")


def epochs_label(r: dict) -> str:
    """``<n> epochs``, the training schedule's length of a report row's network."""
    n = ((r.get("config") or {}).get("train") or {}).get("epochs")
    return "epochs unknown" if n is None else f"{n} epochs"


#: Optimizer names of `optimizer_label` (`learn.config.OPTIMIZERS`).
OPTIMIZER_NAMES = {"sgdm": "SGDM", "adam": "Adam", "adamw": "AdamW"}


def optimizer_label(r: dict) -> str:
    """``<optimizer> wd <weight decay>`` of a report row's training (`learn.config.TrainConfig`;
    ``optimizer unknown`` when its checkpoint does not say)."""
    train = (r.get("config") or {}).get("train") or {}
    if not train.get("optimizer"):
        return "optimizer unknown"
    name = OPTIMIZER_NAMES.get(train["optimizer"], train["optimizer"])
    return f"{name} wd {train.get('weight_decay', 0):g}"


def trained_precision(r: dict) -> str:
    """``fp32`` or ``bf16``, the number format of a report row's training forward pass
    (`learn.train.RunConfig.precision`; checkpoints from before it was recorded: fp32)."""
    return (r.get("config") or {}).get("precision") or "fp32"


def precision_label(r: dict) -> str:
    """``<fp32|bf16> training``, a report row's `trained_precision` as a label."""
    return f"{trained_precision(r)} training"


def views_label(r: dict) -> str:
    """The training views of a report row's network: ``no flips``, ``flips`` (the paper's
    three views) or ``flips + 180°`` (`learn.train.RunConfig.rot180`, a fourth), then
    `` + shifts ±<n> px`` for random shifts (`learn.train.RunConfig.shift_px`) and `` + mixup
    α <a>`` for mixup (`learn.train.RunConfig.mixup_alpha`)."""
    cfg = r.get("config") or {}
    flips = "flips" if cfg.get("flips", True) else "no flips"
    shift, alpha = cfg.get("shift_px") or 0, cfg.get("mixup_alpha") or 0.0
    return (
        flips
        + (" + 180°" if cfg.get("rot180") else "")
        + (f" + shifts ±{shift} px" if shift else "")
        + (f" + mixup α {alpha:g}" if alpha else "")
    )


def averaging_label(r: dict) -> str:
    """``EMA <decay>`` or ``no EMA``: a report row's weight averaging
    (`learn.config.TrainConfig.ema_decay`; checkpoints from before it existed: none)."""
    decay = ((r.get("config") or {}).get("train") or {}).get("ema_decay") or 0.0
    return f"EMA {decay:g}" if decay else "no EMA"


def smoothing_label(r: dict) -> str:
    """``label smoothing <eps>`` or ``no label smoothing`` of a report row's training loss
    (`learn.config.TrainConfig.label_smoothing`; checkpoints from before it existed: none)."""
    eps = ((r.get("config") or {}).get("train") or {}).get("label_smoothing") or 0.0
    return f"label smoothing {eps:g}" if eps else "no label smoothing"


def types_label(r: dict) -> str:
    """``type head <weight>`` or ``no type head``: a report row's auxiliary contactor-type loss
    (`learn.train.RunConfig.aux_types_weight`; checkpoints from before it existed: none)."""
    weight = (r.get("config") or {}).get("aux_types_weight") or 0.0
    return f"type head {weight:g}" if weight else "no type head"


def teacher_label(r: dict) -> str:
    """``distilled from <teacher's run folder> (a <weight>, T <temperature>)`` or ``no
    teacher``: a report row's knowledge distillation (`learn.train.RunConfig.distill_from`;
    checkpoints from before it existed: none)."""
    cfg = r.get("config") or {}
    if not cfg.get("distill_from"):
        return "no teacher"
    teacher = Path(str(cfg["distill_from"]))
    return (
        f"distilled from {teacher.parent.name or teacher.name} (a "
        f"{cfg.get('distill_weight', 0.5):g}, T {cfg.get('distill_temperature', 4.0):g})"
    )


def init_label(r: dict) -> str:
    """``from scratch`` (seeded random weights), ``from <run folder>`` (fine-tuned from that
    run's checkpoint, ``handskin train --init``) or ``init unknown`` (not recorded)."""
    init = r.get("init")
    if init is None:
        return "init unknown"
    return "from scratch" if init == "random" else f"from {Path(str(init)).parent.name or init}"


def dropout_label(r: dict) -> str:
    """``dropout x <scale>`` or ``paper's dropout``: a report row's factor on HandsNet's dropout
    rates (`learn.config.ModelConfig.dropout_scale`; checkpoints from before it existed: 1)."""
    k = ((r.get("config") or {}).get("model") or {}).get("dropout_scale", 1.0)
    return "paper's dropout" if k == 1 else f"dropout x {k:g}"


def width_label(r: dict) -> str | None:
    """``w<multiplier>`` of a report row's network (None: no width multiplier configured)."""
    width = ((r.get("config") or {}).get("model") or {}).get("width")
    return None if width is None else f"w{width:g}"
