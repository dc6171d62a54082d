"""The figures that describe a set of prints (`tactile.prints.measures.Prints`), each with its
spread.

    prints = read_prints(ds)
    rows = [(name, group_figures(prints, mask)) for name, mask in groups(prints)]
    shares = part_shares(prints, prints.kind == "hand")        # % of pixels and of pressure
    values = anchored_values(prints)                           # what `tactile.prints.anchors` holds

Every figure is an `Estimate`: the value over the dataset and the 95 % percentile bootstrap over
its samples (or its subjects, for who pressed), seeded; None where the dataset lacks what the
figure needs ("not in this dataset": no force field, no part labels, no contactor descriptions).
Shares are of sums over samples (a part's pixels over all labelled hand pixels), as the seed
paper's Fig. 10 counts them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tactile.images.labels import CLASS_NAMES
from tactile.prints.measures import Prints, bootstrap_mean, bootstrap_share

PARTS = CLASS_NAMES[1:]  # thumb, index, middle, ring, pinkie, palm
FINGERS = ("index", "middle", "ring", "pinkie")  # the four fingers (thumb apart)
DIGITS = ("thumb", *FINGERS)
# Per-sample statistics of `Prints` shown by group: (attribute, header with unit).
GROUP_STATS: tuple[tuple[str, str], ...] = (
    ("active", "active taxels"),
    ("area_mm2", "area (mm²)"),
    ("blobs", "blobs"),
    ("blobs_grey", "blobs before morphology"),
    ("parts", "parts per hand"),
    ("force_n", "force (N)"),
)


@dataclass(frozen=True)
class Estimate:
    """A figure: its value, the 95 % bootstrap interval [low, high] and the count n (samples or
    subjects) it rests on; in the figure's unit (%, cm, N, mm², count)."""

    value: float
    low: float
    high: float
    n: int


def _estimate(triple: tuple[float, float, float], n: int) -> Estimate | None:
    return Estimate(*triple, n) if n and np.isfinite(triple[0]) else None


def is_grasp(action: np.ndarray) -> np.ndarray:
    """(S,) bool: the grasps of the seed paper (grasp, grasp + twist cw / ccw)."""
    return np.char.startswith(np.asarray(action, dtype=str), "grasp")


def groups(prints: Prints) -> list[tuple[str, np.ndarray]]:
    """(name, (S,) bool mask): all hand prints, the hand prints of each action (in the dataset's
    order), the grasps together, then each non-hand contactor kind."""
    hand = prints.kind == "hand"
    out = [("hand", hand)] if hand.any() else []
    present = set(prints.action[hand].tolist())
    actions = [a for a in dict.fromkeys([*prints.actions, *sorted(present)]) if a in present and a]
    out += [(f"hand: {a}", hand & (prints.action == a)) for a in actions]
    if sum(a.startswith("grasp") for a in actions) > 1:
        out.append(("hand: all grasps", hand & is_grasp(prints.action)))
    kinds = [k for k in dict.fromkeys(prints.kind.tolist()) if k != "hand"]
    return out + [(k, prints.kind == k) for k in kinds]


def group_figures(prints: Prints, mask: np.ndarray, seed: int = 0) -> dict[str, Estimate | None]:
    """`GROUP_STATS` attribute -> mean over the samples of ``mask``; parts per hand only where
    the dataset has part labels and the group holds hands, force only where it was recorded."""
    out: dict[str, Estimate | None] = {}
    for stat, _ in GROUP_STATS:
        missing = (stat == "force_n" and "force_n" not in prints.fields) or (
            stat == "parts" and (not prints.has_labels or not (prints.kind[mask] == "hand").all())
        )
        values = getattr(prints, stat)[mask]
        out[stat] = None if missing else _estimate(bootstrap_mean(values, seed=seed), mask.sum())
    return out


def part_shares(prints: Prints, mask: np.ndarray, seed: int = 0) -> dict[str, Estimate | None]:
    """% of the labelled hand pixels (``pixels.<part>``) and of the hand's summed pressure
    (``pressure.<part>``) each part holds over the samples of ``mask``, and ``thumb_touch``:
    % of them whose thumb presses at least one active taxel. None without part labels."""
    n = int(mask.sum())
    if not prints.has_labels or not n:
        return dict.fromkeys(
            [f"{w}.{p}" for w in ("pixels", "pressure") for p in PARTS] + ["thumb_touch"]
        )
    out = {}
    for what, table in (("pixels", prints.part_pixels), ("pressure", prints.part_pressure_pa)):
        rows = table[mask].astype(float)
        for k, part in enumerate(PARTS, start=1):
            out[f"{what}.{part}"] = _percent(
                bootstrap_share(rows[:, k], rows[:, 1:].sum(1), seed=seed), n
            )
    touch = (prints.part_active[mask, 1] > 0).astype(float)
    out["thumb_touch"] = _percent(bootstrap_mean(touch, seed=seed), n)
    return out


def _percent(triple: tuple[float, float, float], n: int) -> Estimate | None:
    return _estimate(tuple(100 * v for v in triple), n)


def digit_shares(prints: Prints, mask: np.ndarray, seed: int = 0) -> dict[str, Estimate | None]:
    """% of the pressure the digits carry over the samples of ``mask``: ``fingers.<finger>`` of
    the four fingers' (as Li 2002 measures force sharing), ``digits.<digit>`` of the five."""
    if not prints.has_labels or not mask.any():
        return dict.fromkeys([f"fingers.{f}" for f in FINGERS] + [f"digits.{d}" for d in DIGITS])
    n, p = int(mask.sum()), prints.part_pressure_pa[mask]
    col = {name: p[:, k] for k, name in enumerate(CLASS_NAMES)}
    four, five = sum(col[f] for f in FINGERS), sum(col[d] for d in DIGITS)
    out = {f"fingers.{f}": _percent(bootstrap_share(col[f], four, seed=seed), n) for f in FINGERS}
    return out | {
        f"digits.{d}": _percent(bootstrap_share(col[d], five, seed=seed), n) for d in DIGITS
    }


def subject_figures(prints: Prints, seed: int = 0) -> dict[str, Estimate | None]:
    """Who pressed, over the distinct subjects of the hand prints: hand length (cm) mean,
    shortest and longest; % right-handed; % male. None where the descriptions lack it."""
    hand = (prints.kind == "hand") & (prints.subject != "")
    _, first = np.unique(prints.subject[hand], return_index=True)
    rows = np.flatnonzero(hand)[np.sort(first)]
    length_cm = 100 * prints.hand_length_m[rows]
    length_cm = length_cm[np.isfinite(length_cm)]
    side, sex = prints.side[rows], prints.sex[rows]
    out: dict[str, Estimate | None] = dict.fromkeys(
        ("length_mean_cm", "length_min_cm", "length_max_cm", "right_pct", "male_pct")
    )
    if length_cm.size:
        out["length_mean_cm"] = _estimate(bootstrap_mean(length_cm, seed=seed), length_cm.size)
        lo, hi = float(length_cm.min()), float(length_cm.max())
        out["length_min_cm"] = Estimate(lo, lo, lo, length_cm.size)
        out["length_max_cm"] = Estimate(hi, hi, hi, length_cm.size)
    for key, column, word in (("right_pct", side, "right"), ("male_pct", sex, "male")):
        known = column[column != ""]
        if known.size:
            out[key] = _percent(bootstrap_mean(known == word, seed=seed), known.size)
    return out


def anchored_values(prints: Prints, seed: int = 0) -> dict[str, Estimate | None]:
    """The figures `tactile.prints.anchors.ANCHORS` name: ``hand.pixels.palm`` (all hand prints),
    ``grasp.fingers.*`` / ``grasp.digits.*`` (the grasps), ``subjects.*``."""
    hand = prints.kind == "hand"
    out = {"hand.pixels.palm": part_shares(prints, hand, seed)["pixels.palm"]}
    grasp = digit_shares(prints, hand & is_grasp(prints.action), seed)
    out |= {f"grasp.{k}": v for k, v in grasp.items()}
    return out | {f"subjects.{k}": v for k, v in subject_figures(prints, seed).items()}
