"""Hand samples: draw (subject, action, operator position) per sample and run the episode.

`sample_hand(index, seed, ctx, subjects)` is sample ``index`` of a hand dataset seeded ``seed``;
it depends only on ``(seed, index)`` and the subject list. ``python -m sim.generate_hands`` writes
the contact sheets ``docs/sheet_hands.png`` (one column per action) and
``docs/sheet_hands_<action>.png`` (12 samples of one action each).
"""

from __future__ import annotations

import argparse
from collections import Counter
from pathlib import Path

import numpy as np

from sim.contactors import ACTIONS, ContactorSpec, PressPlan
from sim.episode import EpisodeContext, run_sample
from sim.interactions import hand_contactor, plan_hand_interaction
from sim.subjects import Subject, sample_subjects

POSITIONS_BY_ACTION = {a: ("free",) if a == "free" else ("front", "side") for a in ACTIONS}


def hand_maker(
    subjects: list[Subject],
    ctx: EpisodeContext,
    action: str | None = None,
    position: str | None = None,
):
    """``make(rng) -> (ContactorSpec, PressPlan)`` for `run_sample`: a random subject, action
    (uniform over `ACTIONS` unless given) and operator position (uniform over the action's)."""

    def make(rng: np.random.Generator) -> tuple[ContactorSpec, PressPlan]:
        subject = subjects[int(rng.integers(len(subjects)))]
        act = action or ACTIONS[int(rng.integers(len(ACTIONS)))]
        choices = POSITIONS_BY_ACTION[act]
        pos = position or choices[int(rng.integers(len(choices)))]
        return hand_contactor(subject), plan_hand_interaction(act, pos, subject, ctx.part, rng)

    return make


def sample_hand(
    index: int,
    seed: int,
    ctx: EpisodeContext,
    subjects: list[Subject],
    keep_sequence: bool = False,
    action: str | None = None,
) -> tuple[dict, Counter]:
    """Sample ``index`` of a hand dataset: (sample dict, reject counts by reason)."""
    return run_sample(index, seed, ctx, hand_maker(subjects, ctx, action), keep_sequence)


def _sheet_samples(ctx: EpisodeContext, subjects: list[Subject], actions: list[str], seed: int):
    """(images, label images, titles) of one hand sample per entry of ``actions`` (index = slot)."""
    images, labels, titles = [], [], []
    for i, action in enumerate(actions):
        sample, _ = sample_hand(i, seed, ctx, subjects, action=action)
        images.append(sample["image"])
        labels.append(sample["label_image"])
        pos = ("front", "side", "free")[int(sample["operator_position"])]
        active = int((sample["pressure_pa"] > ctx.cfg.active_pa).sum())
        titles.append(f"{action} ({pos}) {float(sample['force_n']):.0f} N, {active} tx")
    return np.stack(images), np.stack(labels), titles


def write_hand_sheet(
    path: Path, n_per_action: int = 4, seed: int = 0, actions: tuple[str, ...] = ACTIONS
) -> Path:
    """Contact sheet of ``n_per_action`` hand samples of each of ``actions``: columns = actions
    (several), or a grid of one action's samples (one action)."""
    from tactile.sheet import save_contact_sheet

    ctx = EpisodeContext()
    subjects = sample_subjects(12, np.random.default_rng(seed))
    slots = [a for _ in range(n_per_action) for a in actions]
    images, labels, titles = _sheet_samples(ctx, subjects, slots, seed)
    what = actions[0] if len(actions) == 1 else "hand interactions"
    return save_contact_sheet(
        path,
        images,
        labels=labels,
        titles=titles,
        n_cols=len(actions) if len(actions) > 1 else 4,
        tile_in=1.9,
        title=f"simulated {what} on the forearm (label colours over the image; tx = active taxels)",
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs"))
    parser.add_argument("--per-action", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(write_hand_sheet(args.out / "sheet_hands.png", args.per_action, args.seed))
    for action in ACTIONS:
        out = args.out / f"sheet_hands_{action}.png"
        print(write_hand_sheet(out, 3 * args.per_action, args.seed + 1, actions=(action,)))


if __name__ == "__main__":
    main()
