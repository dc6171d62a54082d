"""Samples pressed by two contactors at once: which second contact, where and when.

A sample of two contacts starts as a single-contact sample would (its first contactor and plan
from the same maker and generator); the second is drawn after it from the same generator: for a
hand, the same person's other hand, another person's hand, an object or a body part (weights of
`sim.generate.config.MixConfig`); for an object a body part, for a body part an object. It presses
at least ``min_gap_mm`` from the first on the flat map (placements are redrawn up to
`MAX_PLACEMENTS` times, then the attempt fails as "no_room") and starts a random delay after it.

Its person or instance lies on the first one's side of the keyed train/test split
(`tactile.dataset.splits.keyed_draws`): a sample then never links a training person or object
to a test one, and the dataset's split holds out whole people and objects as before.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from sim.contactors.interactions import hand_contactor, plan_hand_interaction
from sim.contactors.nonhand import instance_id_for, mixture, pressed_instance
from sim.contactors.placement import draw_aim_taxel
from sim.contactors.spec import ACTIONS, ContactorSpec, PressPlan
from sim.contactors.subjects import Subject
from sim.episode.runner import EpisodeContext, EpisodeFailure, Maker
from sim.generate.hands import POSITIONS_BY_ACTION
from tactile.dataset.splits import TRAIN_FRACTION, keyed_draws

MIX_STREAM = 2**31 + 2  # keyed draw of whether sample i holds two contacts
SECOND_DELAY_S = (0.0, 0.3)  # the second contact starts this much later (uniform), s
MAX_PLACEMENTS = 20  # redraws of the second contact's site before the attempt fails
SECONDS = ("same_person", "two_people", "hand_object", "hand_body")


def is_mix_index(i: int, seed: int, fraction: float) -> bool:
    """Whether sample ``i`` holds two contacts: a uniform draw keyed by (seed, i), below
    ``fraction`` (independent of the attempt, so a retried sample keeps its kind)."""
    return fraction > 0 and np.random.default_rng([seed, MIX_STREAM, i]).random() < fraction


def in_train(kind: int, group_id: int, seed: int) -> bool:
    """The keyed split's side of a person (kind 0) or an object instance (kind 1)."""
    return bool(keyed_draws(np.array([[kind, group_id]]), seed)[0] < TRAIN_FRACTION)


def subject_number(subject: Subject) -> int:
    """The integer id a dataset stores for a person ("s0007" -> 7)."""
    return int(subject.subject_id.lstrip("s") or -1)


def other_hand(subject: Subject) -> Subject:
    """The same person with their other hand."""
    side = "left" if subject.hand.side == "right" else "right"
    return replace(subject, hand=replace(subject.hand, side=side))


@dataclass(frozen=True)
class SecondContact:
    """What a mix sample's second contact is drawn from: the people, the instance pools
    (``instances`` per type), the weights of a hand's second (`SECONDS`), the gap (mm) and the
    dataset seed (the keyed split's)."""

    ctx: EpisodeContext
    subjects: list[Subject]
    instances: int
    weights: tuple[float, float, float, float]
    min_gap_mm: float
    seed: int

    def maker(self, first: Maker) -> Maker:
        """``first``'s maker, followed by a second contact from the same generator."""

        def make(rng: np.random.Generator) -> tuple[list, list]:
            c1, p1 = first(rng)
            p1 = self.placed(p1, rng)
            c2, p2 = self.second(c1, p1, rng)
            delay = rng.uniform(*SECOND_DELAY_S)
            p2 = replace(p2, durations_s=(p2.durations_s[0] + delay, *p2.durations_s[1:]))
            return [c1, c2], [p1, p2]

        return make

    def placed(self, plan: PressPlan, rng: np.random.Generator) -> PressPlan:
        """``plan`` with its site drawn (the runner's aim policy) when it has none."""
        if plan.site_uv is not None:
            return plan
        uv = self.ctx.part.flat_mm[draw_aim_taxel(self.ctx.part, rng)]
        return replace(plan, site_uv=(float(uv[0]), float(uv[1])))

    def second(self, first: ContactorSpec, plan: PressPlan, rng: np.random.Generator):
        """The second (contactor, plan), placed at least the gap from ``plan``'s site."""
        side = in_train(*self.group(first), self.seed)
        if first.kind != "hand":
            kind = "body" if first.kind == "object" else "object"
            return self.nonhand(kind, side, plan, rng)
        w = np.asarray(self.weights, float)
        which = SECONDS[int(rng.choice(len(SECONDS), p=w / w.sum()))]
        if which in ("hand_object", "hand_body"):
            return self.nonhand(which.removeprefix("hand_"), side, plan, rng)
        person = self.person(first, which, side, rng)
        action = ACTIONS[int(rng.integers(len(ACTIONS)))]
        choices = POSITIONS_BY_ACTION[action]
        position = choices[int(rng.integers(len(choices)))]
        for _ in range(MAX_PLACEMENTS):
            p2 = plan_hand_interaction(action, position, person, self.ctx.part, rng)
            if self.apart(plan, p2):
                return hand_contactor(person), p2
        raise EpisodeFailure("no_room", f"no site {self.min_gap_mm:g} mm from the first hand")

    def group(self, c: ContactorSpec) -> tuple[int, int]:
        """(kind, id) of a contactor's group in the keyed split: its person, else its instance."""
        return (0, c.subject_id) if c.subject_id >= 0 else (1, c.instance_id)

    def person(self, first: ContactorSpec, which: str, side: bool, rng) -> Subject:
        """The second hand's person: the first's other hand, or someone else on its side."""
        owner = next(s for s in self.subjects if subject_number(s) == first.subject_id)
        if which == "same_person":
            return other_hand(owner)
        pool = [s for s in self.subjects if s is not owner]
        pool = [s for s in pool if in_train(0, subject_number(s), self.seed) == side] or pool
        return pool[int(rng.integers(len(pool)))]

    def nonhand(self, kind: str, side: bool, plan: PressPlan, rng):
        """An object or body part on ``side`` of the split, pressed away from ``plan``'s site."""
        table = {name: w for (k, name), w in mixture().items() if k == kind}
        names, w = list(table), np.array(list(table.values()))
        name = names[int(rng.choice(len(names), p=w / w.sum()))]
        ids = [instance_id_for(kind, name, j) for j in range(self.instances)]
        ids = [i for i in ids if in_train(1, i, self.seed) == side] or ids
        spec, p2 = pressed_instance(kind, name, ids[int(rng.integers(len(ids)))], rng)
        for _ in range(MAX_PLACEMENTS):
            placed = self.placed(p2, rng)
            if self.apart(plan, placed):
                return spec, placed
        raise EpisodeFailure("no_room", f"no site {self.min_gap_mm:g} mm from the first contact")

    def apart(self, a: PressPlan, b: PressPlan) -> bool:
        """Whether the two plans' sites lie at least the gap apart on the flat map."""
        gap = np.hypot(*(np.subtract(a.site_uv, b.site_uv)))
        return bool(gap >= self.min_gap_mm)
