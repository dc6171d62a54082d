"""Tables (the layout of the paper's Tables 11-14) and charts of the robustness studies.

Inputs are the dicts of ``experiments.studies.blind_spot_study`` and ``removal_study``; scores
are in %, as mean ± sd over the random patterns (the charts add the min-max band). Paper values
come only from ``learn.evaluate.paper``; every other paper cell reads "unknown".
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure

from experiments.report import SEG_LABELS, markdown_table, pm
from experiments.studies import scores_pct, spread, summarize
from learn.evaluate import paper

SPREAD = ("mean", "sd", "min", "max")  # the keys of a spread dict
TEXT = {"ha": "center", "va": "center", "fontsize": 7}  # heat-map cell labels
#: the paper's HandsNet accuracy (%) by share of taxels removed: Table 13's known cell, and at
#: 0 % the intact skin's accuracy (Table 3)
PAPER_REMOVAL_PCT = {0.0: paper.HANDSNET_ACCURACY_PCT, **paper.TEST_B_CLASSIFICATION_PCT}


def _paper_cell(fraction: float) -> str | None:
    value = PAPER_REMOVAL_PCT.get(round(fraction, 2))
    if value is None:
        return None
    return f"{value:.2f}" + (" (Table 3, intact skin)" if fraction == 0 else "")


def setup_text(data, prep, truth: str) -> str:
    """The report's setup section: data, subsets, networks (``prep``: a ``Prepared``), and
    ``truth``, how the ground truth of a corruption is made."""
    f = prep.frames
    segmented = f", {len(f.segment)} hand samples segmented" if len(f.segment) else ""
    lines = [
        f"Dataset `{data}`: test split of {f.n_split} samples; {len(f.classify)} classified"
        f"{segmented} (seeded subsets when fewer than all; every pattern is drawn from --seed). "
        "Images are regenerated from the raw readings through the corrupted map "
        "(`TactileMap.image`), label images with `tactile.images.labels.label_image`.",
        "",
    ]
    for m in prep.info:
        how = "given" if m["given"] else "trained here"
        size = tuple(m["model"]["input_size"])
        lines.append(
            f"- {m['name']}: `{m['checkpoint']}` ({how}; best epoch {m['epochs']}; {size} px)"
        )
    return "\n".join([*lines, "", truth])


def baseline_table(cms: dict, models) -> str:
    """Scores (%) on the regenerated, uncorrupted test images."""
    rows = [
        [m.name, ", ".join(f"{k} {v:.2f}" for k, v in scores_pct(cms[m.name], m.task).items())]
        for m in models
    ]
    return markdown_table(["network", "scores (%)"], rows)


def spot_summaries(study: dict, name: str, task: str) -> dict[tuple[int, float], dict]:
    """{(N_s, r mm): {score: spread}} of one model in a Test A study."""
    return {
        (c["n_spots"], c["radius_mm"]): summarize(c["cm"][name], task) for c in study["conditions"]
    }


def removal_summaries(study: dict, name: str, task: str) -> list[tuple[float, dict]]:
    """[(share removed, {score: spread})] of one model in a Test B study; with ``p_d`` (% of
    ground-truth hand pixels discarded) and ``n_kept`` (taxels)."""
    out = []
    for c in study["conditions"]:
        s = summarize(c["cm"][name], task)
        lost = np.asarray(c["discarded_px"], float) / np.maximum(c["hand_px"], 1)
        out.append(
            (c["fraction"], {**s, "p_d": spread(100.0 * lost), "n_kept": spread(c["n_kept"])})
        )
    return out


def _grid(summ: dict[tuple[int, float], dict]) -> tuple[list[int], list[float]]:
    return sorted({k[0] for k in summ}), sorted({k[1] for k in summ})


def table_11(summ: dict[tuple[int, float], dict]) -> str:
    """Classification accuracy (%) under blind spots: rows N_s, columns r (mm)."""
    ns, rs = _grid(summ)
    rows = [[n, *(pm(summ[(n, r)]["accuracy"]) if (n, r) in summ else "–" for r in rs)] for n in ns]
    return markdown_table(["N_s \\ r", *(f"{r:g} mm" for r in rs)], rows)


def table_12(summ: dict[tuple[int, float], dict]) -> str:
    """Segmentation scores (%) under blind spots, one row per (N_s, r)."""
    head = ["N_s", "r (mm)", *SEG_LABELS.values(), "paper"]
    rows = [
        [n, f"{r:g}", *(pm(s[k]) for k in SEG_LABELS), None] for (n, r), s in sorted(summ.items())
    ]
    return markdown_table(head, rows)


def table_13(curves: Mapping[str, list[tuple[float, dict]]]) -> str:
    """Classification accuracy (%) by share of taxels removed, per model, with the paper's."""
    names = list(curves)
    head = ["removed %", "taxels kept", *(f"{n} acc %" for n in names), "paper acc %"]
    rows = [
        [f"{100 * f:g}", f"{s['n_kept']['mean']:.0f}"]
        + [pm(curves[n][i][1]["accuracy"]) for n in names]
        + [_paper_cell(f)]
        for i, (f, s) in enumerate(curves[names[0]])
    ]
    return markdown_table(head, rows)


def table_14(curves: Mapping[str, list[tuple[float, dict]]]) -> str:
    """Segmentation scores (%) and p_d (%) by share of taxels removed, per model."""
    head = ["model", "removed %", *SEG_LABELS.values(), "p_d %", "paper"]
    rows = [
        [name, f"{100 * f:g}", *(pm(s[k]) for k in SEG_LABELS), pm(s["p_d"]), None]
        for name, curve in curves.items()
        for f, s in curve
    ]
    return markdown_table(head, rows)


def heatmaps(summ: dict[tuple[int, float], dict], keys: Sequence[str], title: str) -> Figure:
    """One heat map per score over (N_s, r mm): mean % in colour, 'mean ± sd' in each cell."""
    ns, rs = _grid(summ)
    fig = Figure(figsize=(4.2 * len(keys), 3.6), layout="constrained")
    for ax, key in zip(np.atleast_1d(fig.subplots(1, len(keys))), keys, strict=True):
        grid, sd = np.full((2, len(ns), len(rs)), np.nan)
        for (n, r), s in summ.items():
            i, j = ns.index(n), rs.index(r)
            grid[i, j], sd[i, j] = s[key]["mean"], s[key]["sd"]
        im = ax.imshow(grid, origin="lower", cmap="viridis", aspect="auto")
        for (i, j), v in np.ndenumerate(grid):
            colour = "w" if v < np.nanmean(grid) else "k"
            ax.text(j, i, f"{v:.1f}\n±{sd[i, j]:.1f}", color=colour, **TEXT)
        label = SEG_LABELS.get(key, key)
        ax.set(xticks=range(len(rs)), xticklabels=[f"{r:g}" for r in rs], yticks=range(len(ns)))
        ax.set(yticklabels=ns, xlabel="blind-spot radius r (mm)", ylabel="number of spots N_s")
        ax.set_title(label)
        fig.colorbar(im, ax=ax, label=f"{label} (%), ours")
    fig.suptitle(f"{title} (paper values unknown to us)")
    return fig


def removal_curves(
    curves: Mapping[str, list[tuple[float, dict]]], keys: Sequence[str], title: str
) -> Figure:
    """Score (%) against taxels removed (%): mean line, ±1 sd bars, min-max band per model;
    the paper's known accuracies as black stars."""
    fig = Figure(figsize=(4.6 * len(keys), 3.8), layout="constrained")
    for ax, key in zip(np.atleast_1d(fig.subplots(1, len(keys))), keys, strict=True):
        for k, (name, curve) in enumerate(curves.items()):
            x = np.array([100 * f for f, _ in curve])
            m, sd, lo, hi = np.array([[s[key][q] for q in SPREAD] for _, s in curve]).T
            ax.fill_between(x, lo, hi, color=f"C{k}", alpha=0.15, label=f"{name} min–max")
            ax.errorbar(x, m, sd, color=f"C{k}", marker="o", capsize=3, label=f"{name} ± 1 sd")
        known = [(100 * f, v) for f, v in PAPER_REMOVAL_PCT.items() if v is not None]
        if key == "accuracy":
            ax.plot(*zip(*known, strict=True), "k*", markersize=12, label="paper (0 %: Table 3)")
        label = "p_d: hand pixels discarded" if key == "p_d" else SEG_LABELS.get(key, key)
        ax.set(xlabel="taxels removed (%)", ylabel=f"{label} (%)", title=label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(title)
    return fig


def write_removal(rep, models, curves: dict, prefix: str) -> None:
    """Tables 13 and 14 and their charts (files ``<prefix>removal_<task>.png``) of Test B
    ``curves`` {model name: removal summaries}."""
    for task, what, number, table, keys in (
        ("classify", "classification", 13, table_13, ["accuracy"]),
        ("segment", "segmentation", 14, table_14, ["pixel_accuracy", "mean_iou", "p_d"]),
    ):
        mine = {m.name: curves[m.name] for m in models if m.task == task}
        if mine:
            title = f"{what.capitalize()} with taxels removed"
            rep.section(f"{title} (paper: Table {number})", table(mine))
            star = "; star: the paper" if task == "classify" else ""
            fig, caption = removal_curves(mine, keys, title), f"{title}: scores (%){star}"
            rep.figure(fig, f"{prefix}removal_{what}.png", caption)


def write_spots(rep, models, study: dict, charts: bool) -> dict:
    """Tables 11 and 12 (and with ``charts`` their heat maps) of Test A ``study``; returns
    {model name: {"N_s,r": {score: spread}}}."""
    out = {}
    for m in models:
        summ = spot_summaries(study, m.name, m.task)
        out[m.name] = {f"{n},{r:g}": v for (n, r), v in summ.items()}
        what, number = ("Classification", 11) if m.task == "classify" else ("Segmentation", 12)
        table = table_11(summ) if m.task == "classify" else table_12(summ)
        title = f"{what} under blind spots (paper: Table {number}): {m.name}"
        rep.section(title, "Scores %, mean ± sd over patterns; paper: unknown.\n\n" + table)
        if charts:
            keys = ["accuracy"] if m.task == "classify" else list(SEG_LABELS)
            fig = heatmaps(summ, keys, m.name)
            rep.figure(fig, f"heatmap_{what.lower()}.png", f"{m.name}: scores (%) over (N_s, r)")
    return out
