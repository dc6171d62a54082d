"""Test score against the number of training samples (or the skin's taxel density), from
`handskin evaluate` reports.

    python docs/data_scaling.py reports/learning.json reports/learning-3x.json \
        reports/learning-hands9k.json --png docs/data_scaling.png
    python docs/data_scaling.py reports/density/*.json --x density --png docs/taxel_density.png

Every row of the given report JSON files (``handskin evaluate --report X.md`` writes ``X.json``)
but ensembles (``--ensemble``) becomes a point: accuracy (classifiers) or mean IoU
(segmenters) in % against the training samples its checkpoint records
(``train_data.n_train``), one line per method and width (dotted with test-time flips), with
the paper's published score as a dashed line. Each report scores its models on its own
dataset's held-out test split, so points of different datasets come from different test
subjects: the bars are the reports' 95 % intervals with test subjects and object instances
redrawn (`learn.cluster_bootstrap`; none for a row that records no groups). A row whose scores
are not held out (``shared_with_training``) is refused.
With ``--x density`` the x axis is the taxel density of each row's training dataset (taxels
per cm² of the tactile map's covered area, read from the dataset, which must be at the path
the checkpoint records), and skins that cover a different share of their map (to the nearest
10 %) get lines of their own.
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import matplotlib
import matplotlib.ticker
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from learn.cluster_bootstrap import grouped_accuracy_interval
from learn.experiments import paper
from learn.row_labels import TTA_SUFFIX, method_label, trained_precision, width_label
from tactile.dataset import open_dataset
from tactile.plot import coverage_mask

PAPER = {"HandsNet": paper.HANDSNET_ACCURACY_PCT, "SegNet": paper.SEGNET_MIOU_PCT}
TASKS = (
    ("classify", "accuracy", "test accuracy, %", "hand / non-hand"),
    ("segment", "mean_iou", "test mean IoU, %", "hand parts (7 classes)"),
)


XLABEL = {
    "train": "training samples (count, log scale; segmenters: hand images)",
    "density": "taxels per cm² of covered skin (log scale)",
}


def skin_density(data_dir: Path) -> tuple[float, float]:
    """(taxels per cm² of the tactile map's covered area, covered share of the map in %) of a
    dataset's part."""
    if not (data_dir / "dataset.h5").is_file():
        raise SystemExit(
            f"--x density needs the training dataset at {data_dir} (dataset.h5 "
            "missing); regenerate it there or score models whose data is present"
        )
    with open_dataset(data_dir) as ds:
        covered = coverage_mask(ds.map)
        per_cm2 = ds.layout.n_taxels / (covered.sum() * ds.map.step_mm**2 / 100.0)
        return per_cm2, 100.0 * covered.mean()


def interval_pct(row: dict) -> tuple[float, float] | None:
    """The row's 95 % interval (lo, hi) in % with test subjects and instances redrawn, or None
    when the row records no groups."""
    if row["task"] == "segment":
        lo_hi = row.get("mean_iou_interval_groups")
    elif row.get("test_groups") is not None and row.get("errors") is not None:
        wrong = [e["index"] for e in row["errors"]]
        right = ~np.isin(np.asarray(row["test_indices"]), wrong)
        lo_hi = grouped_accuracy_interval(right, row["test_groups"])
    else:
        lo_hi = None
    return None if lo_hi is None else (100 * lo_hi[0], 100 * lo_hi[1])


def points(paths: list[Path], x: str = "train") -> dict[str, dict[str, list[tuple]]]:
    """{task: {line: [(x, score %, dataset name, interval % or None), ...]}} of the reports'
    rows; x is the training samples (``x="train"``) or the taxel density per cm²
    (``x="density"``, lines also split by covered share)."""
    out: dict[str, dict[str, list]] = defaultdict(lambda: defaultdict(list))
    for path in paths:
        for row in json.loads(path.read_text()):
            if row.get("members"):  # an ensemble (--ensemble): not one network's data scaling
                continue
            shared = row.get("shared_with_training") or {}
            if shared.get("test_samples"):
                raise SystemExit(
                    f"{path}: {row['checkpoint']} is scored on subjects it "
                    "was trained on; score it on its own dataset's test split"
                )
            data = row.get("train_data") or {}
            if data.get("n_train") is None:
                raise SystemExit(f"{path}: {row['checkpoint']} does not record its training data")
            key = {task: metric for task, metric, _, _ in TASKS}[row["task"]]
            line = method_of(row)
            if x == "train":
                where = int(data["n_train"])
            else:
                where, covered = skin_density(Path(data["path"]))
                line += f", {10 * round(covered / 10):.0f} % covered"
            out[row["task"]][line].append(
                (where, 100 * row["metrics"][key], Path(data["path"]).name, interval_pct(row))
            )
    return out


def method_of(row: dict) -> str:
    """A row's line: the method's name, its width multiplier when it has one, ``bf16`` when it
    was trained in bfloat16 (`learn.train.RunConfig.precision`), and whether it was scored with
    test-time flips (``handskin evaluate --tta``)."""
    width = width_label(row)
    bf16 = " bf16" if trained_precision(row) == "bf16" else ""
    return (
        method_label(row)
        + ("" if width is None else f" {width}")
        + (bf16 + (TTA_SUFFIX if row.get("tta_views") else ""))
    )


def _spread(ticks: list[float], ratio: float = 1.2) -> list[float]:
    """Ascending ``ticks`` without those closer than ``ratio`` to the last kept one (log axis:
    their labels would overlap)."""
    kept: list[float] = []
    for t in ticks:
        if not kept or t >= kept[-1] * ratio:
            kept.append(t)
    return kept


def chart(pts: dict, png: Path, x: str = "train") -> Path:
    """Two panels (classification, segmentation), score against training samples (or taxel
    density, ``x="density"``)."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, (task, _, ylabel, title) in zip(axes, TASKS, strict=True):
        drawn = set()  # methods whose paper line is drawn
        labels = []  # (train samples, score %, text, colour) of every point
        for method, rows in sorted(pts.get(task, {}).items()):
            rows = sorted(rows, key=lambda r: r[:3])
            style = "o:" if method.split(",")[0].endswith(TTA_SUFFIX) else "o-"
            line = ax.plot([r[0] for r in rows], [r[1] for r in rows], style, label=method)[0]
            for n, score, _, span in rows:
                if span is not None:
                    ax.errorbar(
                        n,
                        score,
                        yerr=[[score - span[0]], [span[1] - score]],
                        color=line.get_color(),
                        capsize=3,
                        lw=1,
                    )
            labels += [
                (n, score, f"{score:.1f} ({name})", line.get_color()) for n, score, name, _ in rows
            ]
            base = method.split(" ")[0].rstrip(",")
            if base in PAPER and base not in drawn:
                drawn.add(base)
                ax.axhline(
                    PAPER[base],
                    ls="--",
                    color=line.get_color(),
                    lw=1,
                    label=f"paper: {base} {PAPER[base]:.2f} %",
                )
        ns = [r[0] for rows in pts.get(task, {}).values() for r in rows]
        ax.set_xscale("log")
        if ns:
            ax.set_xlim(min(ns) / 1.3, max(ns) * 1.8)
        ax.xaxis.set_major_formatter(matplotlib.ticker.ScalarFormatter())
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        lo, hi = ax.get_xlim()
        ticks = (500, 1000, 2000, 3000, 5000, 10000, 20000, 50000) if x == "train" else ns
        ax.set_xticks(_spread(sorted({round(t, 2) for t in ticks if lo <= t <= hi})))
        ax.margins(y=0.12)
        _label_points(ax, labels)
        ax.set(xlabel=XLABEL[x], ylabel=ylabel, title=title)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="lower right" if task == "classify" else "upper left")
    what = (
        "More synthetic data: test score against training set size"
        if x == "train"
        else "Denser skin: test score against taxel density"
    )
    fig.suptitle(f"{what} (each point on its own dataset's held-out subjects)", fontsize=10)
    fig.tight_layout()
    fig.savefig(png, dpi=110)
    return png


def spread(ys: list[float], gap: float) -> list[float]:
    """Label heights for points at heights ``ys`` (one x): each label at its point, moved down
    just enough to sit ``gap`` below the label above it (same order as ``ys``)."""
    out, last = [0.0] * len(ys), None
    for i in sorted(range(len(ys)), key=lambda i: -ys[i]):
        out[i] = ys[i] if last is None else min(ys[i], last - gap)
        last = out[i]
    return out


def _label_points(ax, labels: list[tuple[float, float, str, str]]) -> None:
    """Write each point's score right of it; labels of points at one x are spread apart so they
    do not overlap (a thin line joins a moved label to its point)."""
    lo, hi = ax.get_ylim()
    gap = 0.045 * (hi - lo)
    by_x: dict[int, list] = defaultdict(list)
    for lab in labels:
        by_x[lab[0]].append(lab)
    lowest = lo
    for n, group in by_x.items():
        heights = spread([score for _, score, _, _ in group], gap)
        lowest = min(lowest, min(heights) - gap)
        for (_, score, text, color), y in zip(group, heights, strict=True):
            line = {"arrowstyle": "-", "lw": 0.5, "color": color}
            ax.annotate(
                text,
                (n, score),
                xytext=(n * 1.06, y),
                textcoords="data",
                fontsize=7,
                color=color,
                va="center",
                arrowprops=line if y != score else None,
            )
    ax.set_ylim(lowest, hi)


def _span(interval: tuple[float, float] | None) -> str:
    return "" if interval is None else f"; {interval[0]:.2f}–{interval[1]:.2f} % subjects redrawn"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("reports", nargs="+", type=Path, help="report JSON files of handskin evaluate")
    ap.add_argument("--png", type=Path, required=True, help="chart to write (PNG path)")
    ap.add_argument(
        "--x",
        choices=sorted(XLABEL),
        default="train",
        help="x axis: training samples (count) or the skin's taxels per cm²",
    )
    args = ap.parse_args()
    pts = points(args.reports, args.x)
    unit = " train" if args.x == "train" else " taxels/cm²"
    for task, methods in pts.items():
        for method, rows in sorted(methods.items()):
            text = ", ".join(
                f"{n:g}{unit}: {s:.2f} % ({d}{_span(i)})"
                for n, s, d, i in sorted(rows, key=lambda r: r[:3])
            )
            print(task, method, text)
    print(f"chart written to {chart(pts, args.png, args.x)}")


if __name__ == "__main__":
    main()
