"""Contact sheets of simulated contacts on the forearm, one tile per sample, for the docs.

    python -m sim.view.sheets [--out docs] [--per-type 3] [--per-action 4] [--seed 0]

writes ``sheet_hands.png`` (one column per action), ``sheet_hands_<action>.png`` (one action's
samples), ``sheet_objects.png`` and ``sheet_body_parts.png`` (every object or body-part type).
Tiles carry the press and the force (N); hand tiles show the label colours over the image and the
number of active taxels (tx).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from sim.contactors.bodyparts import BODY_KINDS
from sim.contactors.nonhand import instance_id_for, pressed_instance
from sim.contactors.objects import OBJECT_KINDS
from sim.contactors.spec import ACTIONS, ContactorSpec, PressPlan
from sim.contactors.subjects import Subject, sample_subjects
from sim.episode.runner import EpisodeContext, run_sample
from sim.generate.hands import sample_hand
from tactile.figures.sheet import save_contact_sheet


def type_maker(kind: str, name: str, instances_per_kind: int = 20):
    """``make(rng) -> (ContactorSpec, PressPlan)`` for `sim.episode.runner.run_sample`: one type
    only."""

    def make(rng: np.random.Generator) -> tuple[ContactorSpec, PressPlan]:
        iid = instance_id_for(kind, name, int(rng.integers(instances_per_kind)))
        return pressed_instance(kind, name, iid, rng)

    return make


def write_sheet(path: Path, kind: str, n_per_type: int = 3, seed: int = 0) -> Path:
    """Contact sheet of ``n_per_type`` pressed samples of every object (or body-part) type."""
    ctx, names = EpisodeContext(), OBJECT_KINDS if kind == "object" else BODY_KINDS
    images, titles = [], []
    for k, name in enumerate(names):
        for i in range(n_per_type):
            sample, _ = run_sample(k * n_per_type + i, seed, ctx, type_maker(kind, name))
            desc = json.loads(sample["contactor"])
            images.append(sample["image"])
            titles.append(f"{name} {desc['press']} {float(sample['force_n']):.0f} N")
    what = "objects" if kind == "object" else "body parts"
    return save_contact_sheet(
        path,
        np.stack(images),
        titles=titles,
        n_cols=2 * n_per_type,
        title=f"simulated {what} pressed on the forearm",
        tile_in=1.9,
    )


def _hand_tiles(ctx: EpisodeContext, subjects: list[Subject], actions: list[str], seed: int):
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
    ctx = EpisodeContext()
    subjects = sample_subjects(12, np.random.default_rng(seed))
    slots = [a for _ in range(n_per_action) for a in actions]
    images, labels, titles = _hand_tiles(ctx, subjects, slots, seed)
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
    parser.add_argument("--out", type=Path, default=Path("docs"), help="output folder")
    parser.add_argument("--per-type", type=int, default=3, help="samples per object type")
    parser.add_argument("--per-action", type=int, default=4, help="hand samples per action")
    parser.add_argument("--seed", type=int, default=0, help="seed of the samples")
    args = parser.parse_args()
    print(write_hand_sheet(args.out / "sheet_hands.png", args.per_action, args.seed))
    for action in ACTIONS:
        out = args.out / f"sheet_hands_{action}.png"
        print(write_hand_sheet(out, 3 * args.per_action, args.seed + 1, actions=(action,)))
    for kind, file in (("object", "sheet_objects.png"), ("body", "sheet_body_parts.png")):
        print(write_sheet(args.out / file, kind, args.per_type, args.seed))


if __name__ == "__main__":
    main()
