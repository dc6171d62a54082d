"""Hand samples: draw (subject, action, operator position) per sample and run the episode.

`sample_hand(index, seed, ctx, subjects)` is sample ``index`` of a hand dataset seeded ``seed``;
it depends only on ``(seed, index)`` and the subject list.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from sim.contactors.interactions import hand_contactor, plan_hand_interaction
from sim.contactors.spec import ACTIONS, ContactorSpec, PressPlan
from sim.contactors.subjects import Subject
from sim.episode.runner import EpisodeContext, run_sample

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
