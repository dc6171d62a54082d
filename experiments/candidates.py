"""The networks that could give the robot's full answer (class, parts, per-taxel labels) in one
core's few milliseconds, scored alike and set on one chart: latency against part localisation
on real prints and against simulated mIoU.

    handskin experiment candidates --data data/paper --real data/real1 --real data/real2 \\
        --candidate "HandsNet + SegNet=runs/handsnet/best.pt,runs/segnet/best.pt" \\
        --candidate "HandParts=runs/handparts/best.pt" --out reports/candidates

A candidate is a class-and-parts network alone, or a classifier and a segmenter. Each gets:
the simulated test split's hand / non-hand accuracy, mIoU and mIoU on the hand's pixels
(`learn.evaluate.scoring`); on every real box folder, hand recall and part localisation
(`learn.evaluate.real`); and the full answer's latency on one thread: the compiled frame path
(`learn.infer.stream.Recognizer`) over the test split's frames, the candidates taking turns
block by block (median and p99 ms; `benchmarks/bench_stream.py` times them at length). The
suggested default is the fastest candidate whose mean real localisation lies within
``margin`` points of the best.
"""

from __future__ import annotations

import json
import platform
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from experiments import experiment
from experiments import options as O
from tactile.dataset import open_dataset
from tactile.dataset.boxes import is_box_folder
from tactile.errors import ConfigError, DataError
from tactile.files import save_figure, write_text_atomic

BLOCK = 250  # frames a candidate answers before the next takes its turn


@dataclass(frozen=True)
class Candidate:
    """A name and its networks: one class-and-parts network, or a classifier and a segmenter."""

    name: str
    networks: tuple[Path, ...]


def parse_candidate(text: str) -> Candidate:
    """``NAME=A.pt[,B.pt]`` (``--candidate``) as a `Candidate`, its files checked."""
    name, sep, files = text.partition("=")
    paths = tuple(Path(f.strip()) for f in files.split(",") if f.strip())
    if not sep or not name.strip() or not 1 <= len(paths) <= 2:
        raise ConfigError(
            f"--candidate {text!r}: give NAME=NETWORK.pt or NAME=CLASSIFIER.pt,SEGMENTER.pt"
        )
    for p in paths:
        if not p.is_file():
            raise DataError(f"--candidate {text!r}: no checkpoint at {p}")
    return Candidate(name.strip(), paths)


def simulated_scores(c: Candidate, data: Path) -> dict:
    """Hand / non-hand accuracy, mIoU and mIoU on the hand's pixels on ``data``'s test split."""
    from learn import metrics as M  # optional: torch (the learn extra)
    from learn.evaluate.scoring import evaluate_checkpoint, report_rows

    rows = [r for p in c.networks for r in report_rows(evaluate_checkpoint(p, data, time_runs=2))]
    clf = next(r for r in rows if r["task"] == "classify")
    seg = next(r for r in rows if r["task"] == "segment")
    hand = M.without_true_class(np.asarray(seg["cm"]))
    return {
        "accuracy": clf["metrics"]["accuracy"],
        "mean_iou": seg["metrics"]["mean_iou"],
        "hand_mean_iou": M.mean_iou(hand),
    }


def real_scores(c: Candidate, folder: Path, negatives: Path) -> dict:
    """Hand recall and part localisation on one real box folder."""
    from learn.evaluate.real import evaluate_real  # optional: torch (the learn extra)

    rows, _ = evaluate_real(folder, list(c.networks), negatives)
    recall = next(r["hand_recall"] for r in rows if "hand_recall" in r)
    localised = next(r["localised"] for r in rows if "localised" in r)
    return {"hand_recall": recall, "localised": localised}


def latencies(candidates: list[Candidate], data: Path, frames: int) -> dict[str, dict]:
    """Per candidate: median and p99 ms of the compiled frame path's full answer (class, parts,
    per-taxel labels) over ``frames`` test frames on one thread, taking turns block by block."""
    import torch  # optional: the learn extra

    from learn.infer.predict import load_map, load_predictor
    from learn.infer.stream import Recognizer, compiled

    torch.set_num_threads(1)
    tmap, _, to_pa = load_map(data)
    with open_dataset(data) as ds:
        pressures = to_pa(ds.raw[np.sort(ds.splits["test"])])
    steps = {}
    for c in candidates:
        preds = [compiled(load_predictor(p)) for p in c.networks]
        steps[c.name] = Recognizer(tmap, *preds).step
    for step in steps.values():
        for p in pressures[:20]:
            step(p)
    times = {name: [] for name in steps}
    for start in range(0, frames, BLOCK):
        block = [pressures[i % len(pressures)] for i in range(start, min(start + BLOCK, frames))]
        for name, step in steps.items():
            for p in block:
                t = time.perf_counter()
                step(p)
                times[name].append(1e3 * (time.perf_counter() - t))
    return {
        n: {"median_ms": float(np.median(t)), "p99_ms": float(np.percentile(t, 99))}
        for n, t in times.items()
    }


def choose(rows: list[dict], margin: float) -> str:
    """The fastest candidate whose mean real localisation is within ``margin`` (points) of the
    best candidate's."""
    best = max(r["real_localised"] for r in rows)
    near = [r for r in rows if 100 * (best - r["real_localised"]) <= margin]
    return min(near, key=lambda r: r["median_ms"])["name"]


def run_candidates(
    candidates: list[Candidate], data: Path, real: list[Path], out: Path, frames: int, margin: float
) -> dict:
    """Score and time every candidate; write results.json, the chart and report.md."""
    if len({c.name for c in candidates}) < len(candidates):
        raise ConfigError("--candidate: two candidates share a name")
    for folder in real:
        if not is_box_folder(folder):
            raise DataError(f"--real {folder}: not a box folder. Fix: handskin ingest-boxes first")
    out.mkdir(parents=True, exist_ok=True)
    timing = latencies(candidates, data, frames)
    rows = []
    for c in candidates:
        row = {"name": c.name, "networks": [str(p) for p in c.networks], **timing[c.name]}
        row |= simulated_scores(c, data)
        row["real"] = {str(f): real_scores(c, f, data) for f in real}
        row["real_localised"] = float(np.mean([r["localised"] for r in row["real"].values()]))
        row["real_recall"] = float(np.mean([r["hand_recall"] for r in row["real"].values()]))
        rows.append(row)
    result = {"rows": rows, "default": choose(rows, margin), "margin_points": margin}
    result |= {"data": str(data), "real": [str(f) for f in real], "frames": frames}
    result["cpu"] = cpu_name()
    write_text_atomic(out / "results.json", json.dumps(result, indent=1))
    chart(rows, result["default"], out / "latency_accuracy.png")
    write_text_atomic(out / "report.md", report(result))
    return result


def cpu_name() -> str:
    """The CPU's model name (Linux's /proc/cpuinfo), else what `platform` knows."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def command(result: dict) -> str:
    """The command line that regenerates ``result`` (its report folder as OUT)."""
    words = ["handskin experiment candidates", f"--data {result['data']}"]
    words += [f"--real {f}" for f in result["real"]]
    words += [f'--candidate "{r["name"]}={",".join(r["networks"])}"' for r in result["rows"]]
    words += [f"--frames {result['frames']}", f"--margin {result['margin_points']:g}", "--out OUT"]
    return " ".join(words)


def chart(rows: list[dict], default: str, png: Path) -> Path:
    from matplotlib.figure import Figure  # start-up: matplotlib
    from matplotlib.ticker import NullFormatter, ScalarFormatter

    xmax = max(r["median_ms"] for r in rows)

    fig = Figure(figsize=(12, 4.8), layout="constrained")
    for ax, key, label in zip(
        fig.subplots(1, 2),
        ("real_localised", "mean_iou"),
        ("parts localised on real prints, % (mean of the folds)", "simulated test mIoU, %"),
        strict=True,
    ):
        for r in rows:
            star = r["name"] == default
            ax.scatter(
                r["median_ms"], 100 * r[key], s=90 if star else 40, marker="*" if star else "o"
            )
            ax.annotate(
                r["name"],
                (r["median_ms"], 100 * r[key]),
                fontsize=8,
                xytext=(4, 4),
                textcoords="offset points",
            )
        ax.axvline(5.0, color="0.5", ls="--", lw=1)
        ax.set_xlabel("full answer on one core, median ms (compiled frame path)")
        ax.set_ylabel(label)
        ax.set_xscale("log")
        ax.xaxis.set_major_formatter(ScalarFormatter())
        ax.xaxis.set_minor_formatter(NullFormatter())
        ax.set_xticks([t for t in (0.5, 1, 2, 3, 5, 8, 13, 20) if t < 2 * xmax])
    fig.suptitle(f"candidates for the full answer (star: the default, {default}); dashed: 5 ms")
    return save_figure(fig, png)


def report(result: dict) -> str:
    rows = result["rows"]
    folders = result["real"]
    head = ["candidate", "median / p99 ms", "sim accuracy %", "sim mIoU %", "sim mIoU hand px %"]
    head += [f"real recall % ({Path(f).name})" for f in folders]
    head += [f"real localised % ({Path(f).name})" for f in folders]
    listed = ", ".join(f"`{f}`" for f in folders)
    lines = [
        "# Candidates for the full answer in a robot's loop",
        "",
        f"Regenerate: `{command(result)}`. Each network trained on the simulated set with "
        "`handskin train DATA --out RUN --arch ARCH` at its preset, its input size and width "
        "as its run.toml says.",
        "",
        f"Simulated test split: `{result['data']}`; real prints: {listed} "
        "(part labels box-derived). Latency: the compiled frame path's full answer on one thread "
        f"over {result['frames']} test frames, median and p99, on one core of "
        f"{result.get('cpu', 'an unnamed CPU')}.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
    ]
    for r in rows:
        cells = [r["name"] + (" (default)" if r["name"] == result["default"] else "")]
        cells += [f"{r['median_ms']:.2f} / {r['p99_ms']:.2f}"]
        cells += [f"{100 * r[k]:.1f}" for k in ("accuracy", "mean_iou", "hand_mean_iou")]
        cells += [f"{100 * r['real'][f]['hand_recall']:.1f}" for f in folders]
        cells += [f"{100 * r['real'][f]['localised']:.1f}" for f in folders]
        lines.append("| " + " | ".join(cells) + " |")
    lines += [
        "",
        f"Default: **{result['default']}**, the fastest candidate within "
        f"{result['margin_points']:g} points of the best mean real localisation.",
        "",
        "![latency against accuracy](latency_accuracy.png)",
    ]
    return "\n".join(lines) + "\n"


@experiment("candidates")
def candidates(
    data: O.opt(Path, "Simulated dataset whose test split scores and times them.", "--data"),
    real: O.opt(list[Path], "Real box folders (handskin ingest-boxes; repeatable).", "--real"),
    candidate: O.opt(
        list[str], "NAME=NETWORK.pt or NAME=CLASSIFIER.pt,SEGMENTER.pt (repeatable).", "--candidate"
    ),
    out: O.OutOpt,
    frames: O.opt(int, "Timed frames per candidate (count).") = 2000,
    margin: O.opt(
        float, "Default: the fastest within this many points of the best (points)."
    ) = 3.0,
) -> Path:
    """Candidates for the full answer: latency against real and simulated accuracy.

    Each candidate scored on the simulated test split and on real prints, and timed on one core
    (the compiled frame path); a chart of latency against localisation on real prints and
    against simulated mIoU, and the fastest candidate near the best real localisation.
    """
    O.check_dataset(data, "--data")
    O.check_at_least("--frames", frames)
    O.check_out(out)
    parsed = [parse_candidate(c) for c in candidate]
    run_candidates(parsed, data, list(real), out, frames, margin)
    return out / "report.md"
