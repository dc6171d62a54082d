"""An action network scored on the held-out people of a dataset with sequences: the confusion
matrix over the actions, the chance levels, the accuracy against the number of 10 Hz frames
seen, by hand (right, left), how the prints of mirror pairs move (`mirror_cues`), and CPU ms
per sequence — the row of ``handskin evaluate`` for an ``action_3d`` checkpoint.

    row = evaluate_action(Path("runs/action/best.pt"), ckpt, model, run, Path("data/actions"))

Frames seen: the answer after k frames is the network's on the press's first k frames, the
others zero (`prefix`), as a robot holds them k / 10 s into the press; nothing after frame k
reaches the network, so every point of the curve is causal.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn

from learn import metrics as M
from learn.config import RunConfig
from learn.data.load import materialize
from learn.data.sequences import FRAME_PERIOD_S, SequenceDataset, frame_times_s, hand_sides
from learn.inputs import mirror_classes
from learn.numerics import flushing
from learn.train.validation import logits_of
from tactile.dataset.reader import DatasetReader
from tactile.prints.motion import hand_axis, print_motion

HANDS = ("right", "left")


@dataclass
class SequenceTest:
    """The test split's presses: ``x`` (S, T, 1, h, w) float32, actions ``y`` (S,) int64, the
    hand of each (S,) str ("right", "left", "" unknown), phase ends (S, 4) s or None."""

    x: torch.Tensor
    y: torch.Tensor
    hands: np.ndarray
    phase_s: np.ndarray | None
    class_names: tuple[str, ...]
    indices: np.ndarray  # (S,) the presses' rows in the dataset


def read_sequence_test(data_path: Path, run: RunConfig, progress: bool = True) -> SequenceTest:
    """The test split of ``data_path`` as ``run``'s network reads it."""
    ds = SequenceDataset(data_path, "test", run.model.input_size, run.model.canvas_mm)
    data = materialize(ds, "test sequences", progress)
    with ds.reader as r:
        hands = hand_sides(r, ds.indices)
        phase = r.seq_phase_s[:][ds.indices] if "seq_phase_s" in r.fields else None
    return SequenceTest(data.x, data.y, hands, phase, ds.class_names, ds.indices)


def _frame_at(t_s: float, n: int) -> int:
    """The last of a press's ``n`` frames read by ``t_s`` s (frame k at 0.1 (k + 1) s)."""
    return int(np.clip(round(t_s / FRAME_PERIOD_S) - 1, 0, n - 1))


def mirror_cues(data_path: Path, test: SequenceTest) -> dict[str, dict] | None:
    """Per action of a mirror pair, how its test presses' prints move from the end of the load
    to the end of the hold (`tactile.prints.motion.print_motion`, in the hand's axes from each
    press's label image): presses, and mean and SD of ``across_mm`` and ``turn_deg``. None without
    mirror pairs, label images or phase times."""
    names, pairs = test.class_names, mirror_pairs(test.class_names)
    wanted = sorted({a for pair in pairs for a in pair})
    with DatasetReader(data_path) as r:
        if not pairs or test.phase_s is None or "label_image" not in r.fields:
            return None
        motions: dict[int, list] = {a: [] for a in wanted}
        for j, i in enumerate(test.indices.tolist()):
            a = int(test.y[j])
            axis = hand_axis(r.map, r.label_image[i]) if a in motions else None
            if axis is None:
                continue
            n = int(r.seq_length[i])
            k = [_frame_at(test.phase_s[j, phase], n) for phase in (1, 2)]  # load, hold ends
            p = r.pressure_from_raw(r.seq_raw[i][k], frame_times_s(n)[k])
            if (p.sum(1) > 0).all():
                motions[a].append(print_motion(p[0], p[1], r.map.uv, axis))
    out = {}
    for a, m in motions.items():
        m = np.asarray(m, float).reshape(-1, 2)
        stats = [
            [float(f(m[:, c])) if len(m) else float("nan") for f in (np.mean, np.std)]
            for c in (0, 1)
        ]
        out[names[a]] = {"n": len(m), "across_mm": stats[0], "turn_deg": stats[1]}
    return out


def prefix(x: torch.Tensor, k: int) -> torch.Tensor:
    """Sequences ``x`` (S, T, ...) with only their first ``k`` frames, the others zero."""
    out = x.clone()
    out[:, k:] = 0
    return out


@flushing()
def prefix_predictions(model: nn.Module, x: torch.Tensor, batch_size: int = 32) -> torch.Tensor:
    """(T, S) int64: the class ``model`` answers for each sequence of ``x`` (S, T, ...) after
    k = 1 .. T frames (row k - 1), from those frames alone."""
    return torch.stack(
        [logits_of(model, prefix(x, k), batch_size).argmax(1) for k in range(1, x.shape[1] + 1)]
    )


def prefix_confusions(pred: torch.Tensor, y: torch.Tensor, num_classes: int) -> torch.Tensor:
    """(K, C, C) int64 confusion matrices (rows true) of predictions ``pred`` (K, S)."""
    return torch.stack([M.confusion_matrix(y, p, num_classes) for p in pred])


def chance_levels(y: torch.Tensor, names: tuple[str, ...]) -> dict[str, object]:
    """Accuracy of guessing: uniformly (1 / C), and always the test split's commonest action."""
    counts = torch.bincount(y, minlength=len(names))
    top = int(counts.argmax())
    return {
        "uniform": 1.0 / len(names),
        "majority": float(counts[top]) / max(1, len(y)),
        "majority_class": names[top],
    }


def mirror_pairs(names: tuple[str, ...]) -> list[tuple[int, int]]:
    """(i, j), i < j, of each mirror pair among ``names`` (`learn.inputs.mirror_classes`)."""
    mirror = mirror_classes(names)
    return [] if mirror is None else [(i, int(j)) for i, j in enumerate(mirror) if i < j]


@flushing()
def cpu_ms_per_sequence(
    model: nn.Module, x: torch.Tensor, threads: int = 1, n_runs: int = 100, rounds: int = 3
) -> float:
    """CPU ms per sequence at batch 1 on ``threads`` torch threads: the least, over ``rounds``,
    of the median over runs on the first ``n_runs`` sequences of ``x`` (S, T, 1, h, w), in turn,
    after 10 warm-up runs."""
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    seqs = [x[i : i + 1] for i in range(min(n_runs, len(x)))]
    best = float("inf")
    try:
        model.eval()
        with torch.inference_mode():
            for s in seqs[:10]:
                model(s)
            for _ in range(rounds):
                times = []
                for i in range(n_runs):
                    tic = time.perf_counter()
                    model(seqs[i % len(seqs)])
                    times.append(time.perf_counter() - tic)
                best = min(best, 1e3 * float(np.median(times)))
    finally:
        torch.set_num_threads(before)
    return best


def by_hand(pred: torch.Tensor, test: SequenceTest) -> dict[str, dict]:
    """Per hand ("right", "left"): its presses' count and prefix confusion matrices."""
    out = {}
    for hand in HANDS:
        sel = torch.from_numpy(test.hands == hand)
        cms = prefix_confusions(pred[:, sel], test.y[sel], len(test.class_names))
        out[hand] = {"n": int(sel.sum()), "prefix_cm": cms.tolist()}
    return out


def evaluate_action(
    path: Path,
    ckpt: Mapping,
    model: nn.Module,
    run: RunConfig,
    data_path: Path,
    *,
    threads: int = 1,
    time_runs: int = 100,
    time_rounds: int = 3,
    progress: bool = True,
) -> dict:
    """The report row of the action network ``model`` (from checkpoint ``ckpt`` at ``path``) on
    the test split of ``data_path``: see the module docstring."""
    test = read_sequence_test(data_path, run, progress)
    names = test.class_names
    pred = prefix_predictions(model, test.x, run.eval_batch_size)
    cms = prefix_confusions(pred, test.y, len(names))
    phase = None if test.phase_s is None else test.phase_s.mean(0).tolist()
    ms = cpu_ms_per_sequence(model, test.x, threads, time_runs, time_rounds)
    return {
        "checkpoint": str(path),
        "arch": run.model.arch,
        "task": run.task,
        "epoch": ckpt["epoch"],
        "seed": ckpt.get("seed"),
        "config": ckpt["config"],
        "init": ckpt.get("init"),
        "class_names": list(names),
        "n_test": len(test.y),
        "cm": cms[-1].tolist(),
        "metrics": {"accuracy": M.accuracy(cms[-1])},
        "chance": chance_levels(test.y, names),
        "frames": list(range(1, len(cms) + 1)),
        "frame_period_s": FRAME_PERIOD_S,
        "prefix_accuracy": [M.accuracy(cm) for cm in cms],
        "prefix_cm": cms.tolist(),
        "hands": by_hand(pred, test),
        "mirror_pairs": [[names[i], names[j]] for i, j in mirror_pairs(names)],
        "mirror_cues": mirror_cues(data_path, test),
        "phase_end_s": phase,
        "ms_per_sequence": ms,
        "threads": threads,
        "time_runs": time_runs,
        "time_rounds": time_rounds,
        "input_size": list(run.model.input_size),
        "canvas_mm": run.model.canvas_mm and list(run.model.canvas_mm),
        "train_data": ckpt.get("data"),
        "train_versions": ckpt.get("versions"),
        "test_data": str(data_path),
        "tta_views": None,
        "int8": None,
    }
