"""Pareto fronts of score against CPU time, their scatter charts and the variants' table.

    on_front = pareto_mask(ms, score)          # (V,) bool: no other variant is faster and better
    fig = pareto_chart(rows, "classify")       # accuracy % vs ms/image (log x), front, paper

A row is one variant's result dict (``experiments.pareto_runs``): ``name``, ``arch``, ``task``
("classify" / "segment"), ``score`` (accuracy or mean IoU, fraction), ``ms_fast`` and
``ms_eval`` (CPU ms per image), ``metrics`` (fractions) and ``training`` (a short text).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter

from experiments.report import SEG_LABELS, markdown_table
from learn.evaluate import paper

#: Published points per task: (label, score %, ms per image), timed on the paper's hardware.
PAPER_POINTS = {
    "classify": ("HandsNet", paper.HANDSNET_ACCURACY_PCT, paper.HANDSNET_MS_PER_IMAGE),
    "segment": ("SegNet", paper.SEGNET_MIOU_PCT, paper.SEGNET_MS_PER_IMAGE),
}
#: Published cells of the variants' table (%), by metric key; every other cell is "unknown".
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
#: Table columns per task: {metric key: header}.
COLUMNS = {"classify": {"accuracy": "accuracy %"}}
COLUMNS["segment"] = {k: f"{v} %" for k, v in SEG_LABELS.items()}


def pareto_mask(ms: Sequence[float], score: Sequence[float]) -> np.ndarray:
    """(V,) bool: variants that no other variant dominates (time ≤, score ≥, one strictly).

    ms : (V,) CPU time per image, ms (lower is better). score : (V,) (higher is better).
    NaN scores are never on the front; identical points are both on it. Sorted by time, then by
    score descending, a variant is on the front when its score beats every one before it.
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
    to ``x_max``: the best score reachable within each time budget."""
    mask = pareto_mask(ms, score)
    order = np.argsort(np.asarray(ms)[mask])
    xs, ys = np.asarray(ms)[mask][order], np.asarray(score)[mask][order]
    return np.append(xs, max(x_max, xs[-1])), np.append(ys, ys[-1])


def _scored(rows: Sequence[dict], task: str) -> tuple[list[dict], np.ndarray]:
    """(the task's rows with a finite score, their front mask)."""
    rows = [r for r in rows if r["task"] == task and np.isfinite(r["score"])]
    return rows, pareto_mask([r["ms_fast"] for r in rows], [r["score"] for r in rows])


def pareto_chart(rows: Sequence[dict], task: str) -> Figure:
    """Scatter of score % against fast-path CPU ms/image (log x) with the front and the paper."""
    rows = _scored(rows, task)[0]
    fig = Figure(figsize=(8, 5), layout="constrained")
    ax = fig.subplots()
    ms, pct = np.array([r["ms_fast"] for r in rows]), 100 * np.array([r["score"] for r in rows])
    for family in dict.fromkeys(r["arch"] for r in rows):
        sel = [i for i, r in enumerate(rows) if r["arch"] == family]
        color, marker, name = FAMILY_STYLE.get(family, ("C7", "D", family))
        ax.scatter(ms[sel], pct[sel], c=color, marker=marker, s=40, label=f"{name} (ours)")
    for x, y, r in zip(ms, pct, rows, strict=True):
        ax.annotate(r["name"], (x, y), textcoords="offset points", xytext=(4, 4), fontsize=7)
    label, score, p_ms = PAPER_POINTS[task]
    if len(rows):
        fx, fy = front_line(ms, pct, max(*ms, p_ms) * 1.5)
        ax.step(fx, fy, where="post", c="k", ls="--", lw=1, label="Pareto front (ours)")
    paper_label = f"paper: {label} ({score:.2f} %, {p_ms:g} ms, paper's hardware)"
    ax.scatter([p_ms], [score], marker="*", s=160, c="C3", edgecolors="k", label=paper_label)
    ax.set_xscale("log")
    ax.xaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.xaxis.set_minor_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
    ax.tick_params(axis="x", which="minor", labelsize=7)
    ax.set_xlabel("CPU time per image, ms (batch 1, 1 thread, fast path; log scale)")
    ax.set_ylabel(f"{SCORE_LABEL[task]}, %")
    what = "Classification" if task == "classify" else "Segmentation"
    ax.set_title(f"{what}: {SCORE_LABEL[task]} against CPU time")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    return fig


def variants_table(rows: Sequence[dict], task: str) -> str:
    """Markdown table of one task's variants (scores %, times ms), front members marked."""
    scored, front = _scored(rows, task)
    on = {r["name"] for r, f in zip(scored, front, strict=True) if f}
    keys = list(COLUMNS[task])
    head = ["variant", "input h×w (px)", "parameters", "training", *COLUMNS[task].values()]
    head += ["CPU ms/image (eval mode)", "CPU ms/image (fast path)", "on front"]
    body = [
        [r["name"], "×".join(map(str, r["size"])), r["params"], r["training"]]
        + [None if r["metrics"].get(k) is None else 100 * r["metrics"][k] for k in keys]
        + [r["ms_eval"], r["ms_fast"], "yes" if r["name"] in on else "no"]
        for r in rows
        if r["task"] == task
    ]
    label, _, p_ms = PAPER_POINTS[task]
    cells = [PAPER_CELLS[task].get(k) for k in keys]
    body.append(
        [f"{label} (paper)", "68×100", None, "published", *cells, None, p_ms, "not compared"]
    )
    return markdown_table(head, body)


def setup_text(rows: Sequence[dict], data: str, config: dict) -> str:
    """The protocol in words: data, budgets, what the times measure."""
    n_test = ", ".join(map(str, sorted({r["n_test"] for r in rows})))
    h, w = config["full_map_px"]
    text = (
        f"Dataset `{data}` (stored image {h}×{w} px); scores on {n_test} test samples (a seeded "
        "subset of the test split when capped). Variants trained here: SGD for a wall-clock "
        f"budget of {config['budget_min']} min each (train samples {config['max_train'] or 'all'}"
        "), the preset's first-phase learning rate and batch, the paper's flips, no validation "
        "(the last weights); variants at other sizes start from the main model where shapes "
        "match. Such short budgets make the scores of the slow variants lower bounds."
    )
    if config["budget_min"] < 1:
        text += (
            " **At this budget networks trained here barely leave chance level**: give the main "
            "models (--classifier, --segmenter) or run without --quick for meaningful scores."
        )
    return text + (
        "\n\nCPU time: `learn.infer.fastpath.cpu_ms_per_image`, the median of the timed runs "
        "after 20 warm-up runs at batch 1 on 1 thread (network forward on a random input), in "
        "eval mode and on the fast path (`fast_inference`: batch norm folded, channels-last, "
        "bf16 weights where the CPU has bf16 kernels and the accuracy stays within 0.5 points); "
        "scores are the fast path's. BoVW and VGG16 + SVM times include feature extraction. The "
        "paper's points are its published scores and times, on its own hardware: shown, not "
        "compared, and not part of our front."
    )


def write_report(rep, rows: list[dict], data) -> dict:
    """Tables, charts and notes into ``rep`` (a ``Report``); returns the results dict."""
    rep.section("Setup", setup_text(rows, str(data), rep.config))
    results: dict = {"rows": rows, "front": {}}
    for task, title in (
        ("classify", "Classification (paper: Table 3)"),
        ("segment", "Segmentation (paper: Table 8)"),
    ):
        scored, mask = _scored(rows, task)
        if not any(r["task"] == task for r in rows):
            continue
        rep.section(f"{title}: {SCORE_LABEL[task]} against CPU time", variants_table(rows, task))
        png = f"pareto_{'classification' if task == 'classify' else 'segmentation'}.png"
        caption = (
            f"Test {SCORE_LABEL[task]} against CPU ms/image (log scale); dashed: our Pareto "
            "front; star: the paper's published model, timed on its hardware"
        )
        rep.figure(pareto_chart(rows, task), png, caption)
        results["front"][task] = [r["name"] for r, m in zip(scored, mask, strict=True) if m]
    results["report"] = str(rep.write(results))
    return results
