"""Reading the fidelity experiment: the rule that picks the default setting, the speed-accuracy
chart, the settings' table and the report's text (``experiments.fidelity`` runs it)."""

from __future__ import annotations

import dataclasses
import math

from experiments import fidelity_settings as FS
from experiments.fidelity_prints import prints_table, same_prints
from experiments.report import markdown_table
from learn.evaluate import paper

MIN_TOL_PT = 1.0  # percentage points: the smallest accuracy loss accepted for speed
Z_95 = 1.959963984540054  # two-sided 95 % normal quantile


def tolerance_pt(best_pct: float, n_test: int) -> float:
    """max(``MIN_TOL_PT``, 1.96 · 100 · sqrt(p (1 − p) / n_test)) with p = best_pct / 100: a
    difference the test set cannot resolve does not buy a slower setting."""
    p = best_pct / 100.0
    return max(MIN_TOL_PT, Z_95 * 100.0 * math.sqrt(max(p * (1 - p), 0.0) / max(n_test, 1)))


@dataclasses.dataclass(frozen=True)
class Choice:
    """Outcome of the rule: chosen index (into the rows), best index, tolerance (points)."""

    index: int
    best: int
    tolerance_pt: float


def choose_default(speeds, accs, n_test: int, same_prints=None) -> Choice | None:
    """The fastest setting (samples per CPU-second) within ``tolerance_pt`` of the best
    accuracy (%) whose prints are the default's (``same_prints[i]``, all True when None); None
    when no setting has both numbers (None = unknown)."""
    same = same_prints or [True] * len(accs)
    ok = [i for i in range(len(accs)) if speeds[i] is not None and accs[i] is not None]
    if not ok:
        return None
    best = max(ok, key=lambda i: accs[i])
    tol = tolerance_pt(accs[best], n_test)
    near = [i for i in ok if accs[i] >= accs[best] - tol]
    near = [i for i in near if same[i]] or near
    return Choice(max(near, key=lambda i: speeds[i]), best, tol)


def _speed(row: dict) -> float:
    return row["per_core"]


def speed_figure(rows: list[dict], key: str, ylabel: str, chosen=None, band=None, paper_line=None):
    """Test metric (%) against generation speed (samples per CPU-second, log x), a point per
    setting in its own colour, named in the legend; the current default a star, the chosen
    setting ringed, a setting that failed named, ``band`` (low, high) % shaded (the rule's
    tolerance), ``paper_line`` (value %, label) dashed."""
    from matplotlib import ticker  # start-up time: matplotlib
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 4.8), layout="constrained")
    ax = fig.subplots()
    pts = sorted((r for r in rows if r["per_core"] and r.get(key) is not None), key=_speed)
    for k, r in enumerate(pts):  # a colour per setting, named in the legend (no crowded labels)
        xy, default = (r["per_core"], r[key]), r["name"] == FS.DEFAULT
        style = {"s": 180, "marker": "*"} if default else {"s": 60}
        name = f"{r['name']} (current default)" if default else r["name"]
        ax.scatter(*xy, zorder=3, c=f"C{k % 10}", label=name, **style)
        if r["name"] == chosen:
            ax.scatter(*xy, s=420, facecolors="none", edgecolors="0.2", label="chosen by the rule")
    for r in rows:  # no point to draw: named in the legend
        if r.get("failed"):
            ax.plot([], [], "x", color="0.5", label=f"{r['name']}: fails (see the report)")
    if band is not None:
        ax.axhspan(*band, color="C2", alpha=0.12, label="within the rule's tolerance of the best")
    if paper_line is not None:
        ax.axhline(paper_line[0], color="0.4", ls="--", lw=1, label=paper_line[1])
    ax.set_xscale("log")
    ax.xaxis.set_major_locator(ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
    ax.xaxis.set_major_formatter("{x:g}")  # plain numbers, not 3 x 10^0
    ax.xaxis.set_minor_formatter("")
    ax.set_xlabel("generation speed (samples per CPU-second, log scale)")
    ax.set_ylabel(ylabel)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)
    ax.set_title("Simulation fidelity: speed against accuracy on the richest setting's test set")
    return fig


def settings_table(rows: list[dict], segmentation: bool) -> str:
    """Markdown: every setting's knobs, generation speed and test accuracy (and mIoU)."""
    head = ["setting", *(h for h, _, _ in FS.KNOB_COLUMNS), "train samples", "workers"]
    head += ["wall samples/s", "samples per CPU-s", "HandsNet acc. %"]
    head += ["SegNet mIoU %"] if segmentation else []
    keys = ["n_train", "workers", "samples_per_s", "per_core", "accuracy_pct", "miou_pct"]
    body = [
        [
            f"`{r['name']}`",
            *(("yes" if v else "no") if isinstance(v, bool) else v for v in r["knobs"]),
        ]
        + [
            "fails" if r.get("failed") and r[k] is None else r[k]
            for k in keys[: len(keys) - (not segmentation)]
        ]
        for r in rows
    ]
    return markdown_table(head, body)


def protocol_text(plan, t, part: str, n_test: int) -> str:
    """The protocol in words: generation, speeds, the shared test set, the probe (``t``: the
    HandsNet probe's TrainConfig)."""
    return (
        f"Each setting generates {plan.n} samples on `{part}` with dataset seed {plan.seed}: the "
        "same presses by the same people and objects in every setting. *Wall samples/s* is over "
        "the wall time from start-up to the merged file; *samples per CPU-s* divides by the CPU "
        "time of the generator and its workers (the speed charted and used by the rule). The "
        f"test set is the test split of `{FS.RICHEST}` ({n_test} samples); every setting trains "
        "on its samples whose person and object are not in it (*train samples*). The probe: "
        f"HandsNet with the `learn.config.HANDSNET` preset's optimiser ({t.optimizer}, lr "
        f"{t.lr:g}, batch {t.batch_size}) for {t.epochs} epochs (lr × {t.lr_drop_factor:g} every "
        f"{t.lr_drop_period_epochs}), input {plan.image_px[0]} × {plan.image_px[1]} px, no flips, "
        "no validation (the last epoch is tested). Its accuracy compares the settings' data; "
        "the paper's number comes from real data and the full schedule."
    )


def choice_text(rows: list[dict], choice: Choice | None, n_test: int) -> str:
    """The rule and its outcome."""
    text = (
        "**Rule.** The default is the fastest setting (samples per CPU-second) whose HandsNet "
        f"accuracy on the shared test set is within max({MIN_TOL_PT:g} point, the 95 % binomial "
        f"half-width of the best accuracy on {n_test} test samples) of the best and whose prints "
        "are the default's (table above).\n\n**Outcome.** "
    )
    if choice is None:
        return text + "unknown: no setting has both a measured speed and accuracy."
    c, b = rows[choice.index], rows[choice.best]
    return text + (
        f"`{c['name']}` ({c['note']}): {c['per_core']:.2f} samples per CPU-second, "
        f"{c['accuracy_pct']:.2f} %; the best is `{b['name']}` at {b['accuracy_pct']:.2f} %, "
        f"the tolerance {choice.tolerance_pt:.2f} points. The current default: `{FS.DEFAULT}`."
    )


PRINTS_TEXT = (
    "Mean of each statistic over the setting's samples of a contactor kind, with its 95 % "
    "bootstrap interval (2,000 resamples of the samples); * marks a mean outside the default's "
    "interval. A setting makes the default's prints when every mean lies inside; the rule below "
    "only picks such a setting (when one is within its accuracy tolerance)."
)


FAILED_TEXT = (
    "A setting fails when, for some sample, none of the generator's attempts at the press "
    "(`episode.max_attempts`, each a fresh seed) could be kept; it is neither timed nor trained."
)


def write_report(rep, rows: list[dict], plan, probe, part: str, test: dict) -> dict:
    """The protocol, the settings' table, the charts and the rule's choice into ``rep`` (a
    ``Report``; ``plan``: the ``FidelityPlan``, ``probe``: the HandsNet probe's TrainConfig);
    writes report.md and results.json and returns the results."""
    accs, n_test = [r["accuracy_pct"] for r in rows], test["n_test"]
    default = next((r for r in rows if r["name"] == FS.DEFAULT and r["prints"] is not None), None)
    same = default and [
        r["prints"] is not None and same_prints(r["prints"], default["prints"]) for r in rows
    ]
    choice = choose_default([r["per_core"] for r in rows], accs, n_test, same)
    rep.section("Protocol", protocol_text(plan, probe, part, n_test))
    rep.section("Settings, speed and accuracy", settings_table(rows, plan.segmentation))
    if default is not None:
        made = [r for r in rows if r["prints"] is not None]
        rep.section("Prints", PRINTS_TEXT + "\n\n" + prints_table(made, FS.DEFAULT))
    failed = [f"- `{r['name']}` ({r['note']}): {r['failed']}." for r in rows if r.get("failed")]
    if failed:
        rep.section("Settings that fail", FAILED_TEXT + "\n\n" + "\n".join(failed))
    picked = None if choice is None else rows[choice.index]["name"]
    band = choice and (accs[choice.best] - choice.tolerance_pt, accs[choice.best])
    for key, net, metric, value, chosen in (
        ("accuracy_pct", "HandsNet", "accuracy", paper.HANDSNET_ACCURACY_PCT, picked),
        ("miou_pct", "SegNet", "mean IoU", paper.SEGNET_MIOU_PCT, None),
    ):
        if key == "miou_pct" and not plan.segmentation:
            continue
        line, label = (value, f"paper: {net} {value} % (real data)"), f"{net} test {metric} (%)"
        fig = speed_figure(rows, key, label, chosen, band if chosen else None, line)
        png = "speed_accuracy.png" if key == "accuracy_pct" else "speed_miou.png"
        what = f"{net} {metric} on the shared test set against generation speed"
        rep.figure(fig, png, f"{what}; star: the current default; ring: chosen by the rule")
    rep.section("Choice of default", choice_text(rows, choice, n_test))
    results = {"settings": rows, "test_set": test}
    results["choice"] = choice and {**dataclasses.asdict(choice), "name": picked}
    rep.write(results)
    return results
