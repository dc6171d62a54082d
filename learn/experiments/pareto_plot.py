"""Pareto fronts of score against CPU time, their scatter charts and the variants table.

    on_front = pareto_mask(ms, score)          # (V,) bool: no other variant is faster and better
    fig = pareto_chart(rows, "classify")       # accuracy % vs ms/image (log x), front, paper
    md = variants_table(rows, "classify")

A row is one variant's result dict (``learn.experiments.pareto``): ``name``, ``task``
("classify" / "segment"), ``score`` (accuracy or mean IoU, fraction), ``ms_fast`` and ``ms_eval``
(CPU ms per image), ``metrics`` (fractions) and ``training`` (a short text).
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter

from learn.experiments import paper
from learn.experiments.report import markdown_table

#: Published points per task: (label, score %, ms per image), timed on the paper's hardware.
PAPER_POINTS: dict[str, tuple[tuple[str, float, float], ...]] = {
    "classify": (("HandsNet", paper.HANDSNET_ACCURACY_PCT, paper.HANDSNET_MS_PER_IMAGE),),
    "segment": (("SegNet", paper.SEGNET_MIOU_PCT, paper.SEGNET_MS_PER_IMAGE),),
}
#: Published cells of the variants table (%), by metric key; every other cell is "unknown".
PAPER_CELLS = {
    "classify": {"accuracy": paper.HANDSNET_ACCURACY_PCT},
    "segment": {"pixel_accuracy": paper.SEGNET_ACC_PCT, "mean_iou": paper.SEGNET_MIOU_PCT},
}
SCORE_LABEL = {"classify": "accuracy", "segment": "mean IoU"}
#: Marker colour, shape and legend name per family of variants.
FAMILY_STYLE = {
    "handsnet": ("C0", "o", "HandsNet"),
    "vgg16": ("C1", "s", "VGG16"),
    "bovw": ("C2", "^", "BoVW"),
    "vgg_svm": ("C4", "v", "VGG16 + SVM"),
    "segnet": ("C0", "o", "SegNet"),
    "fcn16s": ("C1", "s", "FCN-16s"),
}
#: Table columns per task: (metric key, header).
COLUMNS = {
    "classify": (("accuracy", "accuracy %"),),
    "segment": (
        ("pixel_accuracy", "Acc %"),
        ("mean_accuracy", "mAcc %"),
        ("mean_iou", "mIoU %"),
        ("fw_iou", "fwIoU %"),
    ),
}


def pareto_mask(ms: Sequence[float], score: Sequence[float]) -> np.ndarray:
    """(V,) bool: variants that no other variant dominates (time ≤, score ≥, one strictly).

    ms : (V,) CPU time per image, ms (lower is better). score : (V,) (higher is better).
    NaN scores are never on the front; identical points are both on it. Sort by time, then by
    score descending; a variant is on the front when its score beats every one before it.
    """
    ms, score = np.asarray(ms, float), np.asarray(score, float)
    mask = np.zeros(len(ms), bool)
    best, best_ms = -np.inf, np.nan
    for i in np.lexsort((-score, ms)):
        tie = score[i] == best and ms[i] == best_ms  # a duplicate of a front point
        if np.isfinite(score[i]) and (score[i] > best or tie):
            mask[i], best, best_ms = True, score[i], ms[i]
    return mask


def front_line(ms: np.ndarray, score: np.ndarray, x_max: float) -> tuple[np.ndarray, np.ndarray]:
    """The front as a step line (``where="post"``): x (K + 1,) ms, y (K + 1,) score, extended
    to ``x_max`` — the best score reachable within each time budget."""
    mask = pareto_mask(ms, score)
    order = np.argsort(np.asarray(ms)[mask])
    xs, ys = np.asarray(ms)[mask][order], np.asarray(score)[mask][order]
    return np.append(xs, max(x_max, xs[-1])), np.append(ys, ys[-1])


def pareto_chart(rows: Sequence[dict], task: str) -> Figure:
    """Scatter of score % against fast-path CPU ms/image (log x) with the front and the paper."""
    rows = [r for r in rows if r["task"] == task and np.isfinite(r["score"])]
    fig = Figure(figsize=(8, 5), layout="constrained")
    ax = fig.subplots()
    ms = np.array([r["ms_fast"] for r in rows])
    pct = 100 * np.array([r["score"] for r in rows])
    for family in dict.fromkeys(r["arch"] for r in rows):
        sel = [i for i, r in enumerate(rows) if r["arch"] == family]
        color, marker, name = FAMILY_STYLE.get(family, ("C7", "D", family))
        ax.scatter(ms[sel], pct[sel], c=color, marker=marker, s=40, label=f"{name} (ours)")
    for x, y, r in zip(ms, pct, rows, strict=True):
        ax.annotate(r["name"], (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
    paper_pts = PAPER_POINTS[task]
    x_max = max([*ms, *(p[2] for p in paper_pts)]) * 1.5
    if len(rows):
        fx, fy = front_line(ms, pct, x_max)
        ax.step(fx, fy, where="post", c="k", ls="--", lw=1, label="Pareto front (ours)")
    for label, score, p_ms in paper_pts:
        ax.scatter(
            [p_ms],
            [score],
            marker="*",
            s=160,
            c="C3",
            edgecolors="k",
            zorder=3,
            label=f"paper: {label} ({score:.2f} %, {p_ms:g} ms, paper's hardware)",
        )
    ax.set_xscale("log")
    plain = FuncFormatter(lambda v, _: f"{v:g}")
    ax.xaxis.set_major_formatter(plain)
    ax.xaxis.set_minor_formatter(plain)
    ax.tick_params(axis="x", which="minor", labelsize=7)
    ax.set(
        xlabel="CPU time per image, ms (batch 1, 1 thread, fast path; log scale)",
        ylabel=f"{SCORE_LABEL[task]}, %",
        title=f"{'Classification' if task == 'classify' else 'Segmentation'}: "
        f"{SCORE_LABEL[task]} against CPU time",
    )
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    return fig


def _pct(v: float | None) -> float | None:
    return None if v is None or not np.isfinite(v) else 100 * float(v)


def variants_table(rows: Sequence[dict], task: str) -> str:
    """Markdown table of one task's variants (scores %, times ms), front members marked."""
    rows = [r for r in rows if r["task"] == task]
    scored = [r for r in rows if np.isfinite(r["score"])]
    front = pareto_mask([r["ms_fast"] for r in scored], [r["score"] for r in scored])
    on = {r["name"] for r, f in zip(scored, front, strict=True) if f}
    keys = [k for k, _ in COLUMNS[task]]
    head = [
        "variant",
        "input h×w (px)",
        "parameters",
        "training",
        *(h for _, h in COLUMNS[task]),
        "CPU ms/image (eval mode)",
        "CPU ms/image (fast path)",
        "resize ms/image",
        "on front",
    ]
    body = [
        [
            r["name"],
            "×".join(map(str, r["size"])),
            r["params"],
            r["training"],
            *(_pct(r["metrics"].get(k)) for k in keys),
            r["ms_eval"],
            r["ms_fast"],
            r["resize_ms"],
            "yes" if r["name"] in on else "no",
        ]
        for r in rows
    ]
    for label, _, p_ms in PAPER_POINTS[task]:
        cells = [PAPER_CELLS[task].get(k) for k in keys]
        body.append(
            [
                f"{label} (paper)",
                "68×100",
                None,
                "published; time on the paper's hardware",
                *cells,
                None,
                p_ms,
                None,
                "not compared",
            ]
        )
    return markdown_table(head, body)


def setup_text(rows: Sequence[dict], data: str, config: dict) -> str:
    """The protocol in words: data, budgets, what the times measure."""
    n_test = sorted({r["n_test"] for r in rows})
    return (
        f"Dataset `{data}` (stored image {config['full_map_px'][0]}×{config['full_map_px'][1]} "
        f"px); scores on {', '.join(map(str, n_test))} test samples (seeded subset of the "
        "subject- and instance-disjoint test split when capped). Variants trained here: SGD "
        f"for a wall-clock budget of {config['budget_min']} min each (max steps "
        f"{config['max_steps'] or 'unset'}, train samples {config['max_train'] or 'all'}), "
        "the preset's first-phase learning rate and batch, the paper's flips, no validation "
        "(last weights); variants at other sizes start from the main model where shapes match "
        f"(warm start: {config['warm_start']}). Such short budgets make the scores of the slow "
        "variants lower bounds."
        + (
            " **At this budget networks trained here barely leave chance level**: give the main "
            "models (--classifier, --segmenter) or use the full setting for meaningful scores."
            if config["budget_min"] < 1
            else ""
        )
        + "\n\n"
        "CPU time: `learn.fastpath.cpu_ms_per_image` — median over the timed runs after 20 "
        "warm-up runs, batch 1, 1 thread, network forward only on a random input, for the model "
        "in eval mode and for the fast path (`fast_inference`: batch norm folded, channels-last,"
        " bf16 weights where this CPU has bf16 kernels and the accuracy stays within 0.5 points"
        "). Scores are those of the fast path. Resizing the stored image to the input size is "
        "listed apart (*resize ms/image*); making the image from the taxels is common to all "
        "and not counted. BoVW and VGG16 + SVM times include feature extraction. The paper's "
        "points are its published scores and times, measured on the paper's hardware: they "
        "are shown, not compared, and not part of our front. This machine's CPU is shared: "
        f"1-minute load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores when the "
        "report was written."
    )


def write_report(rep, rows: list[dict], not_run: list[str], data) -> dict:
    """Tables, charts and notes into ``rep`` (a ``Report``); returns the results dict."""
    rep.section("Setup", setup_text(rows, str(data), rep.config))
    results: dict = {"rows": rows, "not_run": not_run, "front": {}}
    for task, title, png in (
        ("classify", "Classification (paper: Table 3)", "pareto_classification.png"),
        ("segment", "Segmentation (paper: Table 8)", "pareto_segmentation.png"),
    ):
        mine = [r for r in rows if r["task"] == task]
        if not mine:
            continue
        rep.section(f"{title}: {SCORE_LABEL[task]} against CPU time", variants_table(rows, task))
        rep.figure(
            pareto_chart(rows, task),
            png,
            f"Test {SCORE_LABEL[task]} against CPU ms/image (log scale); the "
            "dashed step line is our Pareto front; the star is the paper's published "
            "model, timed on the paper's hardware (not comparable with ours).",
        )
        scored = [r for r in mine if np.isfinite(r["score"])]
        mask = pareto_mask([r["ms_fast"] for r in scored], [r["score"] for r in scored])
        results["front"][task] = [r["name"] for r, m in zip(scored, mask, strict=True) if m]
    rep.section("Not run", "\n".join(f"- {t}" for t in not_run) or "Everything listed ran.")
    results["report"] = str(rep.write(results))
    return results
