"""Reading the fidelity experiment: the rule that picks the default setting, the speed–accuracy
chart and the settings table.

Rule (`choose_default`): among the settings with a measured speed and accuracy, take the fastest
(samples per CPU-second, which other jobs on a shared machine change little) whose accuracy is
within a tolerance of the best; the tolerance is the larger of `MIN_TOL_PT`
and the 95 % binomial half-width of the best accuracy on the ``n_test`` test samples, so that a
difference the test set cannot resolve does not buy a slower setting.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from handskin import fidelity_settings as FS
from learn.experiments.report import markdown_table

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from handskin.fidelity import FidelityPlan
    from learn.experiments.report import Report
    from sim.gen_config import GenerateConfig

MIN_TOL_PT = 1.0  # percentage points: the smallest accuracy loss accepted for speed
Z_95 = 1.959963984540054  # two-sided 95 % normal quantile


@dataclass(frozen=True)
class Choice:
    """Outcome of the rule: chosen index (into the rows), best index, tolerance (points)."""

    index: int
    best: int
    tolerance_pt: float


def tolerance_pt(best_pct: float, n_test: int) -> float:
    """max(`MIN_TOL_PT`, 1.96 · 100 · sqrt(p (1 − p) / n_test)) with p = best_pct / 100."""
    p = best_pct / 100.0
    return max(MIN_TOL_PT, Z_95 * 100.0 * math.sqrt(max(p * (1 - p), 0.0) / max(n_test, 1)))


def choose_default(
    speeds: Sequence[float | None], accs: Sequence[float | None], n_test: int
) -> Choice | None:
    """The fastest setting within the tolerance of the best accuracy (%); None if no setting has
    both numbers. speeds : samples/s (None = unknown); accs : % (None = unknown)."""
    ok = [
        i
        for i, (s, a) in enumerate(zip(speeds, accs, strict=True))
        if s is not None and a is not None
    ]
    if not ok:
        return None
    best = max(ok, key=lambda i: accs[i])
    tol = tolerance_pt(accs[best], n_test)
    near = [i for i in ok if accs[i] >= accs[best] - tol]
    return Choice(max(near, key=lambda i: speeds[i]), best, tol)


def choice_text(rows: list[dict], choice: Choice | None, default: str, n_test: int) -> str:
    """The report's closing paragraph: the rule, its outcome, and where the default stands."""
    rule = (
        "**Rule.** The default is the fastest setting (samples per CPU-second) whose HandsNet "
        f"accuracy on the shared test set is within max({MIN_TOL_PT:g} point, the 95 % "
        f"binomial half-width of the best accuracy on {n_test} test samples) of the best."
    )
    if choice is None:
        return rule + "\n\n**Outcome.** unknown: no setting has both a measured speed and accuracy."
    c, b = rows[choice.index], rows[choice.best]
    out = (
        f"{rule} Here the best is `{b['name']}` at {b['accuracy_pct']:.2f} %, the tolerance "
        f"{choice.tolerance_pt:.2f} points.\n\n**Outcome.** `{c['name']}` "
        f"({c['note']}): {c['per_core']:.2f} samples per CPU-second, "
        f"{c['accuracy_pct']:.2f} %."
    )
    now = next((r for r in rows if r["name"] == default), None)
    if now is None:
        return out + f" The current default `{default}` was not run."
    if c["name"] == default:
        return out + " It is the current default."
    if now["per_core"] is None or now["accuracy_pct"] is None:
        return out + f" The current default `{default}` has no measured speed (unknown)."
    return (
        out + f" The current default `{default}` runs at {now['per_core']:.2f} samples per "
        f"CPU-second ({now['per_core'] / c['per_core']:.2f} × `{c['name']}`'s) at "
        f"{now['accuracy_pct']:.2f} % ({b['accuracy_pct'] - now['accuracy_pct']:.2f} points "
        f"below the best): by this rule `{c['name']}` should become the default (a decision "
        "for the maintainers, who also weigh what the data is for beyond hand / non-hand "
        "accuracy, e.g. sequences or segmentation)."
    )


def settings_table(rows: list[dict], knob_headers: Sequence[str], segnet: bool) -> str:
    """Markdown: every setting's knobs, generation speed, and test accuracy (and mIoU)."""
    head = [
        "setting",
        *knob_headers,
        "train samples",
        "rejected episodes",
        "workers",
        "load avg",
        "wall samples/s",
        "samples per CPU-s",
        "HandsNet acc. %",
    ]
    head += ["SegNet mIoU %"] if segnet else []
    body = []
    for r in rows:
        row = [
            f"`{r['name']}`",
            *[_knob(v) for v in r["knobs"]],
            r["n_train"],
            r["rejects"],
            r["workers"],
            r["load_avg"],
            r["samples_per_s"],
            r["per_core"],
            r["accuracy_pct"],
        ]
        body.append(row + ([r.get("miou_pct")] if segnet else []))
    return markdown_table(head, body)


def _knob(v: object) -> object:
    if isinstance(v, bool):
        return "yes" if v else "no"
    return v if isinstance(v, str) else float(v)


def speed_figure(
    rows: list[dict],
    key: str,
    ylabel: str,
    default: str,
    chosen: str | None,
    paper: tuple[float, str] | None = None,
    band: tuple[float, float] | None = None,
) -> Figure:
    """Scatter of test metric (%) against generation speed (samples per CPU-second, log x), one
    labelled point per setting; the current default as a star, the chosen setting ringed,
    ``band`` (low, high) % shaded (the rule's tolerance), the paper's number as a dashed line
    labelled "paper"."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import NullFormatter

    fig, ax = plt.subplots(figsize=(7.5, 4.8))
    pts = sorted(
        (r for r in rows if r["per_core"] and r.get(key) is not None), key=lambda r: r["per_core"]
    )
    others = [r["name"] for r in pts if r["name"] != default]
    for k, r in enumerate(pts):
        is_default = r["name"] == default
        first = bool(others) and r["name"] == others[0]
        label = "current default" if is_default else ("setting" if first else None)
        ax.scatter(
            r["per_core"],
            r[key],
            s=160 if is_default else 60,
            marker="*" if is_default else "o",
            color="C3" if is_default else "C0",
            zorder=3,
            label=label,
        )
        ax.annotate(
            r["name"],
            (r["per_core"], r[key]),
            textcoords="offset points",
            xytext=(6, 5 if _above_neighbour(pts, k, key) else -12),
            fontsize=8,
        )
    for r in pts:
        if r["name"] == chosen:
            ax.scatter(
                r["per_core"],
                r[key],
                s=420,
                facecolors="none",
                edgecolors="C2",
                linewidths=2,
                zorder=4,
                label="chosen by the rule",
            )
    if band is not None:
        ax.axhspan(*band, color="C2", alpha=0.12, label="within the rule's tolerance of the best")
    if paper is not None:
        ax.axhline(paper[0], color="0.4", ls="--", lw=1, label=paper[1])
    ax.set_xscale("log")
    ax.margins(y=0.08)
    ax.set_xlabel("generation speed (samples per CPU-second, log scale)")
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)
    if pts:  # ticks at the measured speeds: a narrow log range may hold no decade tick
        xs = np.array([r["per_core"] for r in pts])
        ax.set_xlim(xs.min() / 1.3, xs.max() * 1.3)
        ticks = spaced(xs)
        ax.set_xticks(ticks, [f"{x:.3g}" for x in ticks])
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.tick_params(axis="x", labelrotation=45)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)
    ax.set_title("Simulation fidelity: speed vs accuracy on the richest setting's test set")
    return fig


def _above_neighbour(pts: list[dict], k: int, key: str) -> bool:
    """Whether point ``k`` is at least as high as its nearest neighbour in log speed (its label
    then goes above it, else below, so that two close points keep their labels apart)."""
    if len(pts) < 2:
        return True
    x = np.log([p["per_core"] for p in pts])
    others = [j for j in range(len(pts)) if j != k]
    j = min(others, key=lambda j: abs(x[j] - x[k]))
    return pts[k][key] >= pts[j][key]


def spaced(values: np.ndarray, min_ratio: float = 1.06) -> list[float]:
    """Sorted ``values`` (> 0) thinned so that neighbours differ by at least ``min_ratio``
    (tick labels on a log axis that do not overlap)."""
    out: list[float] = []
    for v in np.sort(values):
        if not out or v >= out[-1] * min_ratio:
            out.append(float(v))
    return out


def write_report(
    report: Report, rows: list[dict], plan: FidelityPlan, rich: GenerateConfig, test: dict
) -> dict:
    """Sections, charts and the choice of default of a run (``report``: a
    `learn.experiments.report.Report`; ``plan``: a `handskin.fidelity.FidelityPlan`; ``rich``:
    the richest setting's GenerateConfig; ``test``: the test set's path, size and timing);
    writes report.md and results.json and returns the results."""
    from learn.experiments import paper

    choice = choose_default(
        [r["per_core"] for r in rows], [r["accuracy_pct"] for r in rows], test["n_test"]
    )
    picked = None if choice is None else rows[choice.index]["name"]
    report.section("Protocol", _protocol_text(plan, rich, test))
    headers = [h for h, _, _ in FS.KNOB_COLUMNS]
    report.section("Settings, speed and accuracy", settings_table(rows, headers, plan.segnet))
    paper_hn = (
        paper.HANDSNET_ACCURACY_PCT,
        f"paper: HandsNet {paper.HANDSNET_ACCURACY_PCT} % (real data, 80 epochs)",
    )
    band = (
        None
        if choice is None
        else (
            rows[choice.best]["accuracy_pct"] - choice.tolerance_pt,
            rows[choice.best]["accuracy_pct"],
        )
    )
    report.figure(
        speed_figure(
            rows, "accuracy_pct", "HandsNet test accuracy (%)", FS.DEFAULT, picked, paper_hn, band
        ),
        "speed_accuracy.png",
        "HandsNet accuracy on the shared test set (richest setting) against "
        "generation speed; star: current default; ring: chosen by the rule",
    )
    if plan.segnet:
        paper_sn = (paper.SEGNET_MIOU_PCT, f"paper: SegNet mIoU {paper.SEGNET_MIOU_PCT} %")
        report.figure(
            speed_figure(rows, "miou_pct", "SegNet test mean IoU (%)", FS.DEFAULT, None, paper_sn),
            "speed_miou.png",
            "SegNet mean IoU on the shared test set against generation speed",
        )
    report.section("Not swept", NOT_SWEPT)
    report.section("Choice of default", choice_text(rows, choice, FS.DEFAULT, test["n_test"]))
    results = {
        "settings": rows,
        "test_set": test,
        "choice": None if choice is None else {**dataclasses.asdict(choice), "name": picked},
    }
    report.write(results)
    return results


NOT_SWEPT = (
    "The issue also names the taxel count. It is fixed by the part (`forearm` and `forearm_8mm` "
    "both carry 768 taxels): another layout is another sensor with another map, not a cheaper "
    "simulation of the same one, so it is not swept here (docs/fidelity.md). `--part` repeats "
    "the sweep on another part. Solver iterations (`solver_1`) and hand detail (`coarse_hand`) "
    "are swept when the settings include them."
)


def _protocol_text(plan: FidelityPlan, rich: GenerateConfig, test: dict) -> str:
    return (
        f"Each setting generates {plan.n} samples on `{rich.part}` with dataset seed {plan.seed} "
        "(the same presses by the same people and objects in every setting) with up to "
        f"{plan.workers} generator process(es). *Wall samples/s* is over the wall time from "
        "start-up to the merged file; *samples per CPU-s* divides by the CPU time of the "
        "generator and its workers, which other jobs on a shared machine change little: it is "
        "the speed charted and used by the rule. The 1-minute load average at the start of each "
        f"generation is listed. The test set is the test split of `{FS.RICHEST}` "
        f"({test['n_test']} samples; people and object instances disjoint from its train "
        "split); every setting trains on its samples whose person and object are not in the "
        f"test split (*train samples*). The probe is HandsNet with {_probe_text(plan)}; its "
        "accuracy measures the data only relative to the other settings (the paper's number "
        "comes from real data and the full schedule)."
    )


def _probe_text(plan: FidelityPlan) -> str:
    """The probe's training, read from its run configuration (preset `learn.config.HANDSNET`)."""
    from handskin.fidelity import probe_run

    t = probe_run("handsnet", plan).train
    return (
        f"the `learn.config.HANDSNET` preset's optimiser ({t.optimizer}, lr {t.lr:g}, batch "
        f"{t.batch_size}) for {t.epochs} epochs (lr × {t.lr_drop_factor:g} every "
        f"{t.lr_drop_period_epochs}), input {plan.image_px[0]} × {plan.image_px[1]} px, no "
        "flips, no validation (the last epoch is tested)"
    )
