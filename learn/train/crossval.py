"""Optional k-fold cross-validation over a small grid of hyper-parameters, folds subject-disjoint.

    grid = parse_grid("train.lr=0.01,0.001;train.batch_size=32,64")
    cv = cross_validate(run, "out/forearm", grid, k=5)       # on the dataset's train split
    cv.best_run, cv.rows                                      # then: fit(cv.best_run, ...)

Samples sharing a subject or an object instance are one group (``tactile.dataset.splits.units``);
``StratifiedGroupKFold`` keeps groups whole and classes balanced across folds. The validation
metric is accuracy (classification) or mean IoU (segmentation); the best mean wins.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from sklearn.model_selection import StratifiedGroupKFold

from learn.config import RunConfig, run_from_dict
from learn.data.load import Data, TensorData, group_ids, materialize, open_split
from learn.train.loop import fit
from tactile.config import to_dict
from tactile.dataset.splits import units
from tactile.errors import ConfigError


def _value(text: str) -> object:
    """A grid value: int, float, true/false, or the text itself."""
    for cast in (int, float):
        try:
            return cast(text)
        except ValueError:
            pass
    return {"true": True, "false": False}.get(text.lower(), text)


def parse_grid(text: str) -> dict[str, list[object]]:
    """``"train.lr=0.01,0.001;train.batch_size=32,64"`` → ``{"train.lr": [0.01, 0.001], ...}``."""
    grid: dict[str, list[object]] = {}
    for part in filter(None, (p.strip() for p in text.split(";"))):
        key, sep, values = part.partition("=")
        if not sep or not values.strip():
            raise ConfigError(f"grid entry {part!r}: write key=v1,v2 (e.g. train.lr=0.01,0.001)")
        grid[key.strip()] = [_value(v.strip()) for v in values.split(",")]
    return grid


def grid_runs(run: RunConfig, grid: Mapping[str, Sequence[object]]) -> list[tuple[dict, RunConfig]]:
    """Every combination of the grid as (changes, validated RunConfig)."""
    if any(k.startswith("model.") for k in grid):
        raise ConfigError("the grid may not change model.* (the data are read once per size)")
    out = []
    for combo in itertools.product(*grid.values()):
        changes = dict(zip(grid, combo, strict=True))
        table: dict = {}
        for key, value in changes.items():
            *parents, leaf = key.split(".")
            node = table
            for p in parents:
                node = node.setdefault(p, {})
            node[leaf] = value
        out.append((changes, run_from_dict(table, run)))
    return out


def folds(ds, k: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """(train positions, val positions) of ``k`` group-disjoint, class-stratified folds."""
    cls, subject, instance = group_ids(ds)
    n = len(ds.indices)
    none = np.full(n, -1)
    groups = units(none if subject is None else subject, none if instance is None else instance)
    strata = np.zeros(n, np.int64) if cls is None else np.asarray(cls, np.int64)
    if len(np.unique(groups)) < k:
        raise ConfigError(f"{k}-fold CV needs at least {k} subjects/instances; found fewer")
    splitter = StratifiedGroupKFold(n_splits=k, shuffle=True, random_state=seed)
    return list(splitter.split(np.zeros(n), strata, groups))


@dataclass
class CVResult:
    """Rows {changes, fold_metrics, mean, std} per grid point; the best run and its changes."""

    rows: list[dict]
    best_run: RunConfig
    best_changes: dict


def cross_validate(
    run: RunConfig,
    path: str | Path,
    grid: Mapping[str, Sequence[object]],
    *,
    k: int = 5,
    hand_classes: Sequence[str] | None = None,
) -> CVResult:
    """k-fold CV of every grid point on the train split of ``path`` (dataset or image folder)."""
    runs = grid_runs(run, grid)
    ds = open_split(
        Path(path),
        "train",
        run.task,
        run.model.input_size,
        hand_classes,
        run.train.seed,
        run.model.canvas_mm,
    )
    full = materialize(ds, "train")
    rows = []
    for changes, cfg in runs:
        scores = [_fold_score(cfg, full, tr, va) for tr, va in folds(ds, k, run.train.seed)]
        rows.append(
            {
                "changes": changes,
                "fold_metrics": scores,
                "mean": float(np.mean(scores)),
                "std": float(np.std(scores)),
            }
        )
    best = int(np.argmax([r["mean"] for r in rows]))
    return CVResult(rows, runs[best][1], runs[best][0])


def _fold_score(run: RunConfig, full: TensorData, train: np.ndarray, val: np.ndarray) -> float:
    """Best validation metric of one fold's training."""
    pick = lambda idx: TensorData(full.x[idx], full.y[idx], full.mirror)  # noqa: E731
    data = Data(pick(train), pick(val), None, (), {"kind": "cv fold"})
    return fit(run, data, None, progress=False).best_metric


def cv_markdown(cv: CVResult) -> str:
    """A markdown table of the CV rows (mean ± std of the validation metric)."""
    lines = ["| changes | mean | std | folds |", "|---|---|---|---|"]
    for r in cv.rows:
        folds_txt = ", ".join(f"{m:.4f}" for m in r["fold_metrics"])
        lines.append(f"| {r['changes']} | {r['mean']:.4f} | {r['std']:.4f} | {folds_txt} |")
    lines.append(f"\nbest: {cv.best_changes} → {to_dict(cv.best_run)['train']}")
    return "\n".join(lines)
