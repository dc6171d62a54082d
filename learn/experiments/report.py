"""The report folder every experiment writes: ``report.md``, ``results.json`` and charts.

rep = Report("robustness-a", out_dir, seed=0, config={"n_patterns": 10})
rep.section("Classification", markdown_table(["N_s", "r (mm)", "acc %"], rows))
rep.figure(fig, "heatmap_accuracy.png", "Accuracy over (N_s, r)")
rep.write(results)   # report.md + results.json, with command, seed, config, versions
"""

from __future__ import annotations

import json
import shlex
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np


def markdown_table(header: Sequence[str], rows: Sequence[Sequence[object]]) -> str:
    """A GitHub markdown table; floats with 2 decimals, ``None`` as "unknown"."""

    def cell(v: object) -> str:
        if v is None:
            return "unknown"
        if isinstance(v, float | np.floating):
            return f"{float(v):.2f}"
        return str(v)

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in rows]
    return "\n".join(lines)


def _plain(value: object) -> object:
    if isinstance(value, Mapping):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, Path):
        return str(value)
    return value


class Report:
    """Collects markdown sections and figures of one experiment, then writes the folder."""

    def __init__(self, name: str, out_dir: str | Path, *, seed: int, config: Mapping) -> None:
        self.name, self.out_dir, self.seed = name, Path(out_dir), int(seed)
        self.config = dict(config)
        self.parts: list[str] = []
        self.started = time.perf_counter()
        self.out_dir.mkdir(parents=True, exist_ok=True)

    def section(self, title: str, body: str) -> None:
        """Add ``## title`` followed by ``body`` (markdown)."""
        self.parts.append(f"## {title}\n\n{body.strip()}\n")

    def figure(self, fig, filename: str, caption: str) -> Path:
        """Save a matplotlib figure (150 dpi) into the folder and reference it in the report."""
        import matplotlib.pyplot as plt

        path = self.out_dir / filename
        fig.savefig(path, dpi=150, bbox_inches="tight")
        plt.close(fig)
        self.parts.append(f"![{caption}]({filename})\n\n*{caption}*\n")
        return path

    def write(self, results: Mapping) -> Path:
        """Write ``report.md`` and ``results.json``; returns the report's path."""
        from learn.checkpoint import versions

        minutes = (time.perf_counter() - self.started) / 60
        vers = versions()
        head = [
            f"# Experiment: {self.name}",
            "",
            f"Command: `{shlex.join(['handskin', *sys.argv[1:]])}`  ",
            f"Seed: {self.seed}. Wall time: {minutes:.1f} min on this machine.  ",
            "Versions: " + ", ".join(f"{k} {v}" for k, v in vers.items()) + ".",
            "",
            "Configuration:",
            "",
            "```json",
            json.dumps(_plain(self.config), indent=1),
            "```",
            "",
            "Numbers marked *paper* are Albini & Cannata (IJRR 2020); *unknown* marks a cell of "
            "the paper's table we do not have.",
            "",
        ]
        path = self.out_dir / "report.md"
        path.write_text("\n".join(head) + "\n" + "\n".join(self.parts))
        payload = {
            "name": self.name,
            "seed": self.seed,
            "config": self.config,
            "versions": vers,
            "wall_time_min": minutes,
            "results": results,
        }
        (self.out_dir / "results.json").write_text(json.dumps(_plain(payload), indent=1))
        return path
