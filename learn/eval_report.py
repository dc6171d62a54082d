"""The markdown report of `handskin evaluate`: our rows beside the paper's Tables 3 and 8, then
per-model details (training data and start, timing, confusion matrix, breakdowns).

    rows = [evaluate_checkpoint("runs/handsnet/best.pt", "out/forearm")]
    write_report(rows, "report.md", header="Data: out/forearm")
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import torch

from learn import metrics as M
from learn.classical import CLASSICAL
from learn.error_sheets import error_text
from learn.evaluate import ARCH_LABEL, PAPER_TABLE3, PAPER_TABLE8, SEG_KEYS
from learn.experiments import paper
from learn.leakage import leakage_note
from learn.row_labels import INT8_SUFFIX, TTA_SUFFIX, data_name, row_labels, trained_precision


def confusion_markdown(cm: torch.Tensor, names: tuple[str, ...]) -> str:
    """A markdown table of a confusion matrix as % of each true class (rows true)."""
    pct = M.percent_by_true_class(cm).numpy()
    head = "| true \\ predicted | " + " | ".join(names) + " |"
    rows = [
        f"| {n} | " + " | ".join(_pct(v) for v in row) + " |"
        for n, row in zip(names, pct, strict=True)
    ]
    return "\n".join([head, "|" + "---|" * (len(names) + 1), *rows])


def _pct(v: float | None) -> str:
    return "–" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.2f}"


def _fmt(v: float | None, scale: float = 1.0) -> str:
    return "unknown" if v is None else f"{scale * v:.2f}"


def trained_on(r: dict) -> str:
    """The "trained on" cell of a report row: its training data, and a warning when test
    samples share subjects or object instances with it (``learn.leakage``)."""
    shared = r.get("shared_with_training") or {}
    leak = shared.get("test_samples")
    if not leak:
        return data_name(r)
    what = [
        name
        for name, key in (("subjects", "subjects"), ("object instances", "instances"))
        if shared.get(key)
    ]
    return data_name(r) + f"; not held out: {leak} test samples share its {' or '.join(what)}"


def _init_text(r: dict) -> str:
    """The report's sentence on where a network's training started (checkpoints record it)."""
    if r.get("timing") or r.get("members"):  # classical, or an ensemble (members listed)
        return ""
    init = r.get("init")
    text = (
        " Initialisation: not recorded (a checkpoint from before it was)."
        if init is None
        else " Initialisation: random (seeded)."
        if init == "random"
        else f" Initialisation: the weights of `{init}`."
    )
    bf16 = trained_precision(r) == "bf16"
    cfg = r.get("config") or {}
    teacher = (
        f" Distilled from `{cfg['distill_from']}` (share {cfg.get('distill_weight'):g} of "
        f"the loss, temperature {cfg.get('distill_temperature'):g})."
        if cfg.get("distill_from")
        else ""
    )
    return text + (" Trained in bfloat16 (autocast forward pass)." if bf16 else "") + teacher


def _ours(rows: list[dict], task: str) -> dict[str, dict]:
    return {lab: r for lab, r in zip(row_labels(rows), rows, strict=True) if r["task"] == task}


def _paper_row(name: str, table: dict, n: int) -> tuple:
    """The paper's values for a label (its method name before any ", ..." suffix)."""
    return table.get(name.split(",")[0], (None,) * n)


def _shown_longer(name: str, ours: dict[str, dict]) -> bool:
    """True when a paper method has no row of its own but rows under longer labels."""
    return name not in ours and any(o.startswith(name + ",") for o in ours)


def _names(paper_table: dict, ours: dict[str, dict]) -> list[str]:
    """Row order of a table: the paper's methods, then ours; a method's int8 row, then its rows
    with test-time flips, right after its plain row."""
    names = list(dict.fromkeys([*paper_table, *ours]))
    for suffix in (TTA_SUFFIX, INT8_SUFFIX):
        plain = [n for n in names if suffix not in n]
        for n in (n for n in names if suffix in n):
            base = n.replace(suffix, "")
            after = [i for i, p in enumerate(plain) if p == base or p.startswith(base + ",")]
            plain.insert(after[-1] + 1 if after else len(plain), n)
        names = plain
    return names


def _not_scored(title: str, kind: str, table: dict, columns: tuple[str, ...]) -> list[str]:
    """The section of a task no row of the report has: one sentence with the paper's known
    values (% but for ms/image) instead of a table of empty rows."""
    cell = lambda c, v: f"{_fmt(v)} ms per image" if c == "ms/image" else f"{c} {_fmt(v)} %"  # noqa: E731
    known = [
        f"{name} "
        + ", ".join(cell(c, v) for c, v in zip(columns, vals, strict=True) if v is not None)
        for name, vals in table.items()
        if any(v is not None for v in vals)
    ]
    paper = f" The paper's values: {'; '.join(known)}." if known else ""
    return [f"## {title}", "", f"No {kind} was scored in this report.{paper}"]


def _table3(rows: list[dict]) -> list[str]:
    ours = _ours(rows, "classify")
    if not ours:
        return _not_scored(
            "Hand / non-hand classification (paper: Table 3)",
            "classifier",
            PAPER_TABLE3,
            ("accuracy", "ms/image"),
        )
    out = [
        "## Hand / non-hand classification (paper: Table 3)",
        "",
        "| method | accuracy % (ours) | CPU ms/image (ours, batch 1) | accuracy % (paper) "
        "| ms/image (paper) | trained on |",
        "|---|---|---|---|---|---|",
    ]
    for name in _names(PAPER_TABLE3, ours):
        if _shown_longer(name, ours):
            continue
        r, (p_acc, p_ms) = ours.get(name), _paper_row(name, PAPER_TABLE3, 2)
        acc = "not run" if r is None else _fmt(r["metrics"]["accuracy"], 100)
        ms = "not run" if r is None else _best_ms(r)
        where = "" if r is None else trained_on(r)
        out.append(f"| {name} | {acc} | {ms} | {_fmt(p_acc)} | {_fmt(p_ms)} | {where} |")
    return out


def _table8(rows: list[dict]) -> list[str]:
    ours = _ours(rows, "segment")
    if not ours:
        return _not_scored(
            "Hand-part segmentation (paper: Table 8)",
            "segmenter",
            PAPER_TABLE8,
            ("Acc", "mAcc", "mIoU", "fwIoU", "ms/image"),
        )
    out = [
        "## Hand-part segmentation (paper: Table 8)",
        "",
        "| method | Acc % | mAcc % | mIoU % | fwIoU % | CPU ms/image (batch 1) "
        "| paper Acc % | paper mAcc % | paper mIoU % | paper fwIoU % | paper ms/image "
        "| trained on |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for name in _names(PAPER_TABLE8, ours):
        if _shown_longer(name, ours):
            continue
        r, paper = ours.get(name), _paper_row(name, PAPER_TABLE8, 5)
        mine = (
            ["not run"] * 5
            if r is None
            else [*(_fmt(r["metrics"][k], 100) for k in SEG_KEYS), _best_ms(r)]
        )
        where = "" if r is None else trained_on(r)
        out.append(f"| {name} | " + " | ".join([*mine, *map(_fmt, paper), where]) + " |")
    return out


def _table8_hand_pixels(rows: list[dict]) -> list[str]:
    """The segmenters' scores on the hand's pixels alone (``M.without_true_class``), with the
    share of the test pixels that are the hand's: what the whole-image Acc and fwIoU hide."""
    ours = {n: r for n, r in _ours(rows, "segment").items() if len(r["cm"]) == 7}
    if not ours:
        return []
    out = [
        "### The same predictions on the hand's pixels",
        "",
        "Scored on the pixels the truth labels as one of the six hand parts only (the "
        "background's pixels left out, a hand pixel predicted as background counted wrong): "
        "the scores of a labelling that marks the hand and leaves the rest unlabelled.",
        "",
    ]
    hand_cms = {n: M.without_true_class(r["cm"]) for n, r in ours.items()}
    shares = {
        round(float(hand_cms[n].sum() / max(int(torch.tensor(r["cm"]).sum()), 1)), 6)
        for n, r in ours.items()
    }
    if len(shares) == 1:
        hand = shares.pop()
        wrong = 1 - paper.SEGNET_ACC_PCT / 100
        out += [
            f"The hand's pixels are {_fmt(hand, 100)} % of the test images' pixels. A "
            f"whole-image Acc of {_fmt(paper.SEGNET_ACC_PCT)} % (the paper's SegNet) would "
            f"leave {_fmt(wrong, 100)} % of the pixels wrong, "
            f"{_fmt(wrong / hand if hand else float('nan'), 100)} % of the hand's pixel "
            f"count, beside an mIoU of {_fmt(paper.SEGNET_MIOU_PCT)} %: on prints like "
            "these the paper's Acc reads more like a score on the hand's pixels (or a "
            "mean class accuracy) than a whole-image one.",
            "",
        ]
    out += ["| method | Acc % | mAcc % | mIoU % | fwIoU % |", "|---|---|---|---|---|"]
    for name, cm in hand_cms.items():
        s = M.segmentation_scores(cm)
        out.append(f"| {name} | " + " | ".join(_fmt(s[k], 100) for k in SEG_KEYS) + " |")
    return out


#: Least fraction of check images (or pixels) on which a compiled network's argmax must equal
#: the float fast path's for the tables to show its time.
COMPILED_AGREEMENT = 0.999


def _best_ms(r: dict) -> str:
    """A row's table ms/image: the fast path's, or the compiled network's (marked) when it was
    timed, is faster and agreed with the fast path on its check images."""
    ms, agree = r["ms_per_image"], r.get("compiled_agreement")
    if (
        ms.get("compiled") is not None
        and ms["compiled"] < ms["fast"]
        and (agree is None or agree >= COMPILED_AGREEMENT)
    ):
        return f"{_fmt(ms['compiled'])} (compiled)"
    return _fmt(ms["fast"])


def _compiled_text(r: dict) -> str:
    """The clause on the compiled network's time, or why it was not timed; "" when not asked."""
    ms, agree = r["ms_per_image"], r.get("compiled_agreement")
    if ms.get("compiled") is not None:
        same = "" if agree is None else f", argmax as the fast path's on {100 * agree:.2f} % of "
        same += "" if agree is None else "64 test images (or their pixels)"
        return f", compiled (torch.compile, frozen weights) {_fmt(ms['compiled'])}{same}"
    return f", compiled: not timed ({note})" if (note := r.get("compile_note")) else ""


def _timing(r: dict) -> str:
    """The sentence on CPU / GPU time per image of a report row."""
    ms, head = r["ms_per_image"], f"CPU ms/image at batch 1, {r['threads']} thread(s): "
    if r.get("timing"):  # a classical model: one path, image to label
        return head + f"{_fmt(ms['fast'])} ({r['timing']})"
    if q := r.get("int8"):  # one path: the int8 network
        saved = (
            f" of {Path(q['calibration_data']).name}, saved by handskin quantize"
            if q.get("saved")
            else ""
        )
        return head + (
            f"{_fmt(ms['fast'])}, int8 ({q['backend']}; activation ranges from "
            f"{q['calibration_images']} images of the {q['calibration_split']} "
            f"split{saved})"
        )
    gpu = "none (no CUDA)" if ms["gpu"] is None else _fmt(ms["gpu"])
    return (
        head + f"eval mode {_fmt(ms['eval_mode'])}, prepared (BN folded) "
        f"{_fmt(ms['prepared'])}, fast path {_fmt(ms['fast'])} "
        f"(bf16 {'on' if r['bf16'] else 'off'}){_compiled_text(r)}; GPU {gpu}"
    )


def _canvas_text(r: dict) -> str:
    canvas = r.get("canvas_mm")  # (H, W) mm of the input canvas; absent or None: stretched
    return "" if canvas is None else f" of a {canvas[0]:g} × {canvas[1]:g} mm canvas"


def _details(r: dict, label: str) -> list[str]:
    names = tuple(r["class_names"]) or tuple(str(i) for i in range(len(r["cm"])))
    epoch = "" if r["epoch"] is None else f"epoch {r['epoch']}, "
    seed = "" if r.get("members") else f"seed {r['seed']}, "
    size = r.get("input_size") or r["config"]["model"]["input_size"]
    return [
        f"### {label} — `{r['checkpoint']}` ({epoch}{seed}{r['n_test']} test images)",
        "",
        f"Trained on: {trained_on(r)}.{_init_text(r)}",
        "",
        *_members_text(r),
        *([note, ""] if (note := leakage_note(r.get("shared_with_training"))) else []),
        f"{_timing(r)}; input (h, w) = {tuple(size)} px{_canvas_text(r)}.",
        "",
        *_tta_text(r),
        "Scores (%): " + ", ".join(f"{k} {_fmt(v, 100)}" for k, v in r["metrics"].items()),
        "",
        "Confusion matrix, % of each true class:",
        "",
        confusion_markdown(torch.tensor(r["cm"]), names),
        "",
        *_by_size(r),
        *error_text(r),
        *_merged(r),
        *_seg_groups(r),
    ]


def _members_text(r: dict) -> list[str]:
    """An ensemble row's list of networks; its scores and times are of their mean softmax."""
    if not r.get("members"):
        return []
    lines = [
        "Ensemble: scores and times are of the mean softmax of these networks "
        "(`learn.ensemble.MeanSoftmax`), each run on the same input:",
        "",
    ]
    for m in r["members"]:
        width = "" if m.get("width") is None else f", w{m['width']:g}"
        lines.append(
            f"- `{m['checkpoint']}`: {ARCH_LABEL.get(m['arch'], m['arch'])}{width}, "
            f"epoch {m['epoch']}, seed {m['seed']}, trained on "
            f"{data_name({'train_data': m['train_data']})}"
            + ("" if not m.get("tta_views") else f", flips over views {m['tta_views']}")
            + "."
        )
    return [*lines, ""]


def _tta_text(r: dict) -> list[str]:
    """The sentence on test-time flips of a row scored with them (its scores and times)."""
    views = r.get("tta_views")
    if not views:
        return []
    batch = (
        "each network runs its views as one batch"
        if r.get("members")
        else f"run as one batch of {len(views)} images"
    )
    return [
        f"Test-time flips: scores and times are of the mean softmax over views {views} "
        "(`learn.tta.VIEW_DIMS`: 0 original, 1 columns reversed, 2 rows reversed, 3 both), "
        f"{batch}.",
        "",
    ]


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
    lines = [
        "IoU per class (%): "
        + ", ".join(f"{n} {_fmt(float(v), 100)}" for n, v in zip(names, ious, strict=True)),
        "",
        "mIoU (%) of coarser groupings of the same predictions:",
        "",
    ]
    for title, groups in MERGED_VIEWS:
        lines.append(f"- {title}: {_fmt(M.mean_iou(M.merge_classes(r['cm'], groups)), 100)}")
    return [*lines, ""]


def _seg_groups(r: dict) -> list[str]:
    """A segmenter row's scores by contactor, action and hand parts touching (handskin data)."""
    from learn.breakdown import segmentation_group_markdown

    groups = r.get("segmentation_by_group")
    if not groups:
        return []
    out = [
        "Scores by group of test images (each group's pooled confusion matrix; contactor and "
        "action lowest mIoU first):",
        "",
    ]
    for title, rows in groups.items():
        out += [*segmentation_group_markdown(rows, title), ""]
    return out


def _by_size(r: dict) -> list[str]:
    """The accuracy-by-contact-size table of a classifier row on a handskin dataset."""
    from learn.breakdown import breakdown_markdown, group_markdown

    if not r.get("by_active_taxels"):
        return []
    out = [
        "Accuracy by contact size (active taxels: pressure above the dataset's active threshold):",
        "",
        *breakdown_markdown(r["by_active_taxels"]),
        "",
    ]
    if r.get("by_force"):
        out += [
            "Accuracy by press force (the dataset's `force_n`: total normal force at the "
            "sampled frame):",
            "",
            *breakdown_markdown(r["by_force"], "press force", "N"),
            "",
        ]
    if r.get("by_contactor"):
        out += [
            "Accuracy by contactor (the dataset's `contactor` kind and type), least accurate "
            "first:",
            "",
            *group_markdown(r["by_contactor"]),
            "",
        ]
    if r.get("hands_by_parts"):
        out += [
            "Accuracy on the hand samples by the hand parts that press (the labels of their "
            "active taxels):",
            "",
            *group_markdown(r["hands_by_parts"], "hand parts"),
            "",
        ]
    if r.get("hands_by_action"):
        out += [
            "Accuracy on the hand samples by action, least accurate first:",
            "",
            *group_markdown(r["hands_by_action"], "action"),
            "",
        ]
    return out


def _significance(rows: list[dict]) -> list[str]:
    """The sections on how sure the rows' accuracies and mIoUs are (`learn.significance`)."""
    from learn.significance import segmentation_markdown, significance_markdown

    labels = row_labels(rows)
    clf = [(r, lab) for r, lab in zip(rows, labels, strict=True) if r["task"] == "classify"]
    return [
        *significance_markdown([r for r, _ in clf], [lab for _, lab in clf]),
        *segmentation_markdown(rows, labels),
    ]


#: An innermost JSON list of numbers, as ``json.dumps(..., indent=1)`` spreads it over lines.
_NUMBER_LIST = re.compile(r"\[(\s*-?[\d.eE+-]+(?:,\s*-?[\d.eE+-]+)*\s*)\]")


def report_json(rows: list[dict]) -> str:
    """The report rows as indented JSON with each innermost list of numbers on one line (a
    segmenter's per-image confusion matrices take ~30 % of the space they would one per line)."""
    return _NUMBER_LIST.sub(
        lambda m: "[" + ", ".join(v.strip() for v in m.group(1).split(",")) + "]",
        json.dumps(rows, indent=1),
    )


def _timing_rule(rows: list[dict]) -> str:
    """How the networks' times per image were taken: interleaved rounds (``time_rounds`` in the
    rows), or for rows from before them, one median per path."""
    specs = sorted({(r["time_runs"], r["time_rounds"]) for r in rows if r.get("time_rounds")})
    if not specs:
        return "median of 100 runs after 20 warm-up runs"
    runs = " or ".join(f"{n}" for n in sorted({n for n, _ in specs}))
    rounds = " or ".join(f"{k}" for k in sorted({k for _, k in specs}))
    one_path = any(r.get("arch") in CLASSICAL and r.get("time_rounds") for r in rows)
    return (
        f"each inference path's median of {runs} runs after 10 warm-up runs, the least over "
        f"{rounds} rounds in which a network's paths (eval mode, prepared, fast, compiled) "
        f"take turns, so that a slow spell of the machine weighs on all of them alike"
        + (
            "; a classical model (BoVW, VGG16 + SVM) has one path, timed in rounds that "
            "follow each other"
            if one_path
            else ""
        )
    )


def write_report(rows: list[dict], path: str | Path, header: str = "") -> Path:
    """The markdown report: our rows next to the paper's Tables 3 and 8 ("paper" columns;
    "unknown" where we do not know the paper's value), then per-model details."""
    lines = [
        "# handskin evaluation",
        "",
        header,
        "",
        "Columns marked *paper* are Albini & Cannata (IJRR 2020); ours are on the test split "
        f"named above. Timing: {_timing_rule(rows)}.",
        "",
        *_table3(rows),
        "",
        *_table8(rows),
        "",
        *_table8_hand_pixels(rows),
        "",
        *_significance(rows),
        "## Details",
        "",
    ]
    for r, label in zip(rows, row_labels(rows), strict=True):
        lines += _details(r, label)
    Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return Path(path)
