"""The folder every experiment writes: ``report.md``, ``results.json`` and PNG charts.

rep = Report("robustness-a", out_dir, seed=0, config={"n_patterns": 10})
rep.section("Classification", markdown_table(["N_s", "r (mm)", "acc %"], rows))
rep.figure(fig, "heatmap_accuracy.png", "Accuracy over (N_s, r)")
rep.write(results)   # report.md and results.json, with command, seed, config, versions
"""

from __future__ import annotations

import json
import shlex
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

#: headers of the segmentation scores (Long et al.'s, as the paper's Table 8), by metric key
SEG_LABELS = dict(pixel_accuracy="Acc", mean_accuracy="mAcc", mean_iou="mIoU", fw_iou="fwIoU")


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A GitHub markdown table; floats with 2 decimals, ``None`` as "unknown"."""

    def cell(v: object) -> str:
        if v is None:
            return "unknown"
        return f"{float(v):.2f}" if isinstance(v, float | np.floating) else str(v)

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return "\n".join(lines + ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows])


def pm(s: Mapping[str, float]) -> str:
    """'mean ± sd' of a spread dict (keys mean, sd), 2 decimals."""
    return f"{s['mean']:.2f} ± {s['sd']:.2f}"


def _json(value: object) -> object:
    """JSON's form of what it cannot write itself: numpy scalars and arrays, paths."""
    return value.tolist() if isinstance(value, np.generic | np.ndarray) else str(value)


class Report:
    """Collects the markdown sections and figures of one experiment, then writes the folder."""

    def __init__(self, name: str, out_dir: str | Path, *, seed: int, config: Mapping) -> None:
        self.name, self.out_dir, self.seed = name, Path(out_dir), int(seed)
        self.config, self.parts, self.started = dict(config), [], time.perf_counter()
        self.out_dir.mkdir(parents=True, exist_ok=True)

    def section(self, title: str, body: str) -> None:
        """Add ``## title`` followed by ``body`` (markdown)."""
        self.parts.append(f"## {title}\n\n{body.strip()}\n")

    def figure(self, fig, filename: str, caption: str) -> None:
        """Save a matplotlib figure (150 dpi) into the folder and show it in the report."""
        import matplotlib.pyplot as plt  # start-up time: matplotlib's pyplot

        path = self.out_dir / filename
        fig.savefig(path, dpi=150, bbox_inches="tight")
        plt.close(fig)
        self.parts.append(f"![{caption}]({filename})\n\n*{caption}*\n")

    def write(self, results: Mapping) -> Path:
        """Write ``report.md`` and ``results.json``; returns the report's path."""
        from learn.train.checkpoint import versions  # optional: torch (the learn extra)

        minutes, vers = (time.perf_counter() - self.started) / 60, versions()
        head = [
            f"# Experiment: {self.name}",
            "",
            f"Command: `{shlex.join(['handskin', *sys.argv[1:]])}`  ",
            f"Seed: {self.seed}. Wall time: {minutes:.1f} min.  ",
            "Versions: " + ", ".join(f"{k} {v}" for k, v in vers.items()) + ".",
            "",
            "Configuration:\n\n```json\n"
            + json.dumps(self.config, indent=1, default=_json)
            + "\n```",
            "",
            "Numbers marked *paper* are Albini & Cannata (IJRR 2020); *unknown* marks a cell of "
            "the paper's table we do not have.",
            "",
        ]
        path = self.out_dir / "report.md"
        path.write_text("\n".join(head) + "\n" + "\n".join(self.parts))
        payload = {"name": self.name, "seed": self.seed, "config": self.config}
        payload |= {"versions": vers, "wall_time_min": minutes, "results": results}
        (self.out_dir / "results.json").write_text(json.dumps(payload, indent=1, default=_json))
        return path
