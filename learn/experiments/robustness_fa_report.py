"""The report of `handskin experiment fault-aware`: plain and fault-aware networks side by side."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from learn.experiments import robustness_plots as P
from learn.experiments.paper import HANDSNET_ACCURACY_60PCT_REMOVED
from learn.experiments.report import Report, markdown_table
from learn.experiments.robustness_setup import (
    baseline_table,
    setup_markdown,
    timing_line,
)

AIM_60PCT = 95.0  # % accuracy at 60 % removed that the issue aims for (paper: 92.67 %)


def _verdict(curves: dict) -> str:
    """One line per classifier: accuracy at 60 % removed against the paper and the aim."""
    lines = []
    for name, curve in curves.items():
        at = {round(f, 2): s for f, s in curve}
        if 0.6 in at:
            a = at[0.6]["accuracy"]
            lines.append(
                f"- {name}: {P.pm(a)} % at 60 % removed (min {a['min']:.2f}); paper "
                f"{HANDSNET_ACCURACY_60PCT_REMOVED} %, aim >= {AIM_60PCT:g} % "
                f"({'met' if a['mean'] >= AIM_60PCT else 'not met'} on the mean)."
            )
    return "\n".join(lines) or "60 % removed was not evaluated."


def _training(scale, trained: list[dict]) -> str:
    rows = [
        [
            t["name"],
            t["from"],
            t.get("epochs", "reused"),
            f"{t['lr']:g}" if "lr" in t else "reused",
            t["train_images"] if t["train_images"] is not None else "reused",
            _minutes(t),
        ]
        for t in trained
    ]
    mix = ", ".join(f"{k} {v}" for k, v in dataclasses.asdict(scale.mix).items())
    return (
        f"Each fault-aware network starts from the plain one and is trained {scale.epochs} "
        f"(classifier, segmenter) more epochs, without flips, on the train part (subsets "
        f"{scale.n_train}, None = all) plus {scale.copies} faulty copies per sample, at "
        f"{scale.lr_factor:g} x the plain run's learning rate; the subject-disjoint "
        "validation part, clean plus as many faulty copies, picks the best epoch. The plain "
        "network gets no extra epochs, "
        "so compare the 0 % rows too. Faults per copy: "
        + mix
        + ".\n\n"
        + markdown_table(
            [
                "network",
                "initialised from",
                "epochs",
                "lr",
                "train images",
                "training (min, epochs' own)",
            ],
            rows,
        )
    )


def _minutes(t: dict) -> str:
    """A network's training minutes: "reused", or its epochs' time (all parts if resumed)."""
    if t["minutes"] is None:
        return "reused"
    return f"{t['minutes']:.1f}" + (" (resumed; all parts)" if t.get("resumed") else "")


def write_report(
    rep: Report, data, scale, models, prep, trained: list[dict], study_a: dict, study_b: dict
) -> Path:
    """report.md, results.json and the charts of a fault-aware run; returns the report's path.

    rep : the run's Report (started before any work). models : [plain classifier, fault-aware
    classifier, plain segmenter, fault-aware segmenter]. prep : the run's
    ``robustness_setup.Prepared``; trained : one dict per fault-aware network.
    """
    info, agree = prep.info, prep.agreement
    rep.section(
        "Setup",
        setup_markdown(data, prep.frames, agree, info, scale.eval)
        + "\n\n"
        + timing_line(prep.minutes),
    )
    rep.section("Fault-aware training", _training(scale, trained))
    rep.section("Zero corruption (regenerated images)", baseline_table(study_a["baseline"], models))
    clfs = [m for m in models if m.task == "classify"]
    segs = [m for m in models if m.task == "segment"]
    curve_c = {m.name: P.removal_summaries(study_b, m.name, "classify") for m in clfs}
    curve_s = {m.name: P.removal_summaries(study_b, m.name, "segment") for m in segs}
    rep.section(
        "Test B: classification with taxels removed (paper: Table 13)",
        P.table_13(curve_c) + "\n\n" + _verdict(curve_c),
    )
    rep.figure(
        P.removal_curves(
            curve_c, ["accuracy"], "Plain vs fault-aware, taxels removed", P.paper_removal_pct()
        ),
        "fa_removal_classification.png",
        "Accuracy (%) against taxels removed (%), plain and fault-aware; star: paper",
    )
    rep.section("Test B: segmentation with taxels removed (paper: Table 14)", P.table_14(curve_s))
    rep.figure(
        P.removal_curves(
            curve_s,
            ["pixel_accuracy", "mean_iou", "p_d"],
            "Plain vs fault-aware segmentation, taxels removed",
        ),
        "fa_removal_segmentation.png",
        "Acc, mIoU and p_d (%) against taxels removed",
    )
    spots = {m.name: P.spot_summaries(study_a, m.name, m.task) for m in models}
    for m in clfs:
        rep.section(
            f"Test A: {m.name} accuracy % under blind spots (paper: Table 11)",
            P.table_11(spots[m.name]),
        )
    for m in segs:
        rep.section(
            f"Test A: {m.name} under blind spots (paper: Table 12)", P.table_12(spots[m.name])
        )
    rep.figure(
        P.spot_bars(
            {m.name: spots[m.name] for m in clfs}, "accuracy", "Blind spots: classification"
        ),
        "fa_spots_classification.png",
        "Accuracy (%) per blind-spot condition, plain and fault-aware",
    )
    rep.figure(
        P.spot_bars({m.name: spots[m.name] for m in segs}, "mean_iou", "Blind spots: segmentation"),
        "fa_spots_segmentation.png",
        "mIoU (%) per blind-spot condition, plain and fault-aware",
    )
    results = {
        "test_a": study_a,
        "test_b": study_b,
        "networks": info,
        "trained": trained,
        "minutes": prep.minutes,
        "curves": {**curve_c, **curve_s},
        "regenerated_vs_stored": agree,
        "spots": {n: {f"{k[0]},{k[1]:g}": v for k, v in s.items()} for n, s in spots.items()},
    }
    return rep.write(results)
