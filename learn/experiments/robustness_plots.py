"""Tables (the layout of the paper's Tables 11-14) and charts of the robustness studies.

Inputs are the dicts of :func:`learn.experiments.robustness_eval.blind_spot_study` and
:func:`~learn.experiments.robustness_eval.removal_study`; scores are in %, as mean ± sd over
the random patterns (min-max in the charts). Paper values come only from
:mod:`learn.experiments.paper`; every other paper cell reads "unknown".
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from matplotlib.figure import Figure

from learn.experiments.paper import HANDSNET_ACCURACY_PCT, TEST_B_CLASSIFICATION_PCT
from learn.experiments.report import markdown_table
from learn.experiments.robustness_eval import SEG_KEYS, spread, summarize

SEG_LABELS = {
    "pixel_accuracy": "Acc",
    "mean_accuracy": "mAcc",
    "mean_iou": "mIoU",
    "fw_iou": "fwIoU",
}
COLOURS = ("C0", "C3", "C2", "C1")


def paper_removal_pct() -> dict[float, float | None]:
    """The paper's HandsNet accuracy (%) by share of taxels removed: Table 13's known cell, and
    at 0 % the intact skin's accuracy of Table 3."""
    return {0.0: HANDSNET_ACCURACY_PCT, **TEST_B_CLASSIFICATION_PCT}


def _paper_cell(fraction: float) -> str | None:
    value = paper_removal_pct().get(round(fraction, 2))
    if value is None:
        return None
    return f"{value:.2f}" + (" (Table 3, intact skin)" if fraction == 0 else "")


def pm(s: Mapping[str, float]) -> str:
    """'mean ± sd' of a spread dict, 2 decimals."""
    return f"{s['mean']:.2f} ± {s['sd']:.2f}"


def spot_summaries(study: dict, name: str, task: str) -> dict[tuple[int, float], dict]:
    """{(N_s, r mm): {score: spread}} of one model in a Test A study."""
    return {
        (c["n_spots"], c["radius_mm"]): summarize(c["cm"][name], task) for c in study["conditions"]
    }


def removal_summaries(study: dict, name: str, task: str) -> list[tuple[float, dict]]:
    """[(fraction removed, {score: spread})] of one model in a Test B study; segmentation adds
    ``p_d`` (% of ground-truth hand pixels discarded) and every model ``n_kept`` (taxels)."""
    out = []
    for c in study["conditions"]:
        s = summarize(c["cm"][name], task)
        lost = np.asarray(c["discarded_px"], float) / np.maximum(c["hand_px"], 1)
        s["p_d"] = spread(100.0 * lost)
        s["n_kept"] = spread(c["n_kept"])
        out.append((c["fraction"], s))
    return out


def _axes_values(summ: dict[tuple[int, float], dict]) -> tuple[list[int], list[float]]:
    return sorted({k[0] for k in summ}), sorted({k[1] for k in summ})


def table_11(summ: dict[tuple[int, float], dict]) -> str:
    """Classification accuracy (%) under blind spots: rows N_s, columns r (mm)."""
    ns, rs = _axes_values(summ)
    rows = [[n, *(pm(summ[(n, r)]["accuracy"]) if (n, r) in summ else "–" for r in rs)] for n in ns]
    return markdown_table(["N_s \\ r", *(f"{r:g} mm" for r in rs)], rows)


def table_12(summ: dict[tuple[int, float], dict]) -> str:
    """Segmentation scores (%) under blind spots, one row per (N_s, r)."""
    head = ["N_s", "r (mm)", *(SEG_LABELS[k] for k in SEG_KEYS), "paper"]
    rows = [
        [n, f"{r:g}", *(pm(s[k]) for k in SEG_KEYS), None] for (n, r), s in sorted(summ.items())
    ]
    return markdown_table(head, rows)


def table_13(curves: Mapping[str, list[tuple[float, dict]]]) -> str:
    """Classification accuracy (%) by share of taxels removed, per model, with the paper's."""
    names = list(curves)
    head = [
        "removed %",
        "taxels kept",
        *(f"{n} acc %" for n in names),
        *(f"{n} min–max" for n in names),
        "paper acc %",
    ]
    rows = []
    for i, (f, s) in enumerate(curves[names[0]]):
        accs = [curves[n][i][1]["accuracy"] for n in names]
        rows.append(
            [
                f"{100 * f:g}",
                f"{s['n_kept']['mean']:.0f}",
                *(pm(a) for a in accs),
                *(f"{a['min']:.2f}–{a['max']:.2f}" for a in accs),
                _paper_cell(f),
            ]
        )
    return markdown_table(head, rows)


def table_14(curves: Mapping[str, list[tuple[float, dict]]]) -> str:
    """Segmentation scores (%) and p_d (%) by share of taxels removed, per model."""
    head = ["model", "removed %", *(SEG_LABELS[k] for k in SEG_KEYS), "p_d %", "paper"]
    rows = [
        [name, f"{100 * f:g}", *(pm(s[k]) for k in SEG_KEYS), pm(s["p_d"]), None]
        for name, curve in curves.items()
        for f, s in curve
    ]
    return markdown_table(head, rows)


def heatmaps(summ: dict[tuple[int, float], dict], keys: Sequence[str], title: str) -> Figure:
    """One heat map per score over (N_s, r mm): mean % in colour, 'mean±sd' in each cell."""
    ns, rs = _axes_values(summ)
    fig = Figure(figsize=(4.2 * len(keys), 3.6), layout="constrained")
    for ax, key in zip(np.atleast_1d(fig.subplots(1, len(keys))), keys, strict=True):
        grid = np.full((len(ns), len(rs)), np.nan)
        for (n, r), s in summ.items():
            grid[ns.index(n), rs.index(r)] = s[key]["mean"]
        im = ax.imshow(grid, origin="lower", cmap="viridis", aspect="auto")
        for (i, j), v in np.ndenumerate(grid):
            sd = summ.get((ns[i], rs[j]), {}).get(key, {}).get("sd", np.nan)
            ax.text(
                j,
                i,
                f"{v:.1f}\n±{sd:.1f}",
                ha="center",
                va="center",
                fontsize=7,
                color="w" if v < np.nanmean(grid) else "k",
            )
        ax.set(
            xticks=range(len(rs)),
            xticklabels=[f"{r:g}" for r in rs],
            yticks=range(len(ns)),
            yticklabels=ns,
            xlabel="blind-spot radius r (mm)",
            ylabel="number of spots N_s",
            title=SEG_LABELS.get(key, key),
        )
        fig.colorbar(im, ax=ax, label=f"{SEG_LABELS.get(key, key)} (%), ours")
    fig.suptitle(f"{title} (paper values unknown to us)")
    return fig


def removal_curves(
    curves: Mapping[str, list[tuple[float, dict]]],
    keys: Sequence[str],
    title: str,
    paper: Mapping[float, float | None] | None = None,
) -> Figure:
    """Score (%) against taxels removed (%): mean line, ±1 sd bars, min-max band per model;
    paper points (where known) as black stars."""
    fig = Figure(figsize=(4.6 * len(keys), 3.8), layout="constrained")
    for ax, key in zip(np.atleast_1d(fig.subplots(1, len(keys))), keys, strict=True):
        for k, (name, curve) in enumerate(curves.items()):
            colour = COLOURS[k % len(COLOURS)]
            x = np.array([100 * f for f, _ in curve])
            m, sd, lo, hi = (
                np.array([s[key][q] for _, s in curve]) for q in ("mean", "sd", "min", "max")
            )
            ax.fill_between(x, lo, hi, color=colour, alpha=0.15, label=f"{name} min–max")
            ax.errorbar(
                x, m, yerr=sd, color=colour, marker="o", capsize=3, label=f"{name} mean ± 1 sd"
            )
        known = [(100 * f, v) for f, v in (paper or {}).items() if v is not None]
        if known and key == "accuracy":
            ax.plot(
                [x for x, _ in known],
                [v for _, v in known],
                "k*",
                markersize=12,
                label="paper (HandsNet; 0 %: Table 3)",
            )
        label = "p_d: hand pixels discarded" if key == "p_d" else SEG_LABELS.get(key, key)
        ax.set(xlabel="taxels removed (%)", ylabel=f"{label} (%)", title=label)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(title)
    return fig


def spot_bars(
    summaries: Mapping[str, dict[tuple[int, float], dict]], key: str, title: str
) -> Figure:
    """Score (%) per (N_s, r) condition for several models side by side (mean ± 1 sd)."""
    names = list(summaries)
    conds = sorted(summaries[names[0]])
    fig = Figure(figsize=(max(6.0, 0.9 * len(conds) + 2), 3.8), layout="constrained")
    ax = fig.subplots()
    width = 0.8 / len(names)
    for k, name in enumerate(names):
        colour = COLOURS[k % len(COLOURS)]
        s = [summaries[name][c][key] for c in conds]
        ax.bar(
            np.arange(len(conds)) + k * width,
            [v["mean"] for v in s],
            width,
            yerr=[v["sd"] for v in s],
            color=colour,
            capsize=2,
            label=name,
        )
    ax.set_xticks(
        np.arange(len(conds)) + 0.4 - width / 2,
        [f"N_s={n}\nr={r:g} mm" for n, r in conds],
        fontsize=7,
    )
    label = SEG_LABELS.get(key, key)
    ax.set(ylabel=f"{label} (%)", xlabel="blind spots (count N_s, radius r)", title=title)
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return fig
