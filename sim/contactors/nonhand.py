"""The non-hand mixture: which object or body part presses, which instance, and how.

Mixture (documented weights, drawn by `sample_nonhand`):
- 65 % objects, 35 % body parts: Albini & Cannata (IJRR 2020) recorded 1,820 non-hand contacts,
  about 35 % of them other body parts (torso, arm, forearm, shoulder, back), the rest objects.
- Objects: the hard negatives (rake, comb, rod bundle: 2-6 parallel finger-like geoms) take 30 %
  (10 % each) because they are what a classifier that counts elongated blobs would call a hand;
  broad objects pressed flat or resting across the link (`BROAD_OBJECTS`: cushion, bundle, big
  ball, plate, box) take 30 % (6 % each): what people carry past, put down on or push against a
  robot in a shared workspace is mostly boxes, trays, bags and clothes, and they are what a
  classifier that measures contact area would call a hand; the 11 other kinds (tools, bottles,
  mugs, small balls: tips and edges) share the remaining 40 % equally (about 3.6 % each).
- Body parts: arms and shoulders lean on a robot arm most (the paper's list: arm, forearm,
  shoulder, torso, back): forearm 20 %, upper arm 15 %, elbow 15 %, shoulder 15 %, chest 10 %,
  back 10 %, knee 8 %, head 7 %.

Instances: each kind has a pool of ``instances_per_kind`` instances (default 20), with global
ids `instance_id_for` (unique across kinds), so a dataset split by instance id holds object and
body-part instances in the test set that training never saw. The press mode is recorded in the
description (``description["press"]``) so it reaches the dataset's contactor JSON.
"""

from __future__ import annotations

from dataclasses import replace
from functools import lru_cache

import numpy as np

from sim.contactors.bodyparts import BODY_KINDS, body_press, build_body_part
from sim.contactors.objects import HARD_NEGATIVES, OBJECT_KINDS, build_object, object_press
from sim.contactors.spec import ContactorSpec, PressPlan
from tactile.errors import ConfigError

OBJECT_FRACTION = 0.65  # Albini & Cannata 2020: ~35 % of non-hand contacts were body parts
HARD_NEGATIVE_SHARE = 0.30  # of objects, split equally among HARD_NEGATIVES
BROAD_OBJECTS: tuple[str, ...] = ("cushion", "bundle", "big_ball", "plate", "box")
BROAD_SHARE = 0.30  # of objects, split equally among BROAD_OBJECTS
BODY_WEIGHTS: dict[str, float] = {
    "forearm": 0.20,
    "upper_arm": 0.15,
    "elbow": 0.15,
    "shoulder": 0.15,
    "chest": 0.10,
    "back": 0.10,
    "knee": 0.08,
    "head": 0.07,
}
MAX_INSTANCES_PER_KIND = 1000  # global id stride per kind
OBJECT_ID_BASE, BODY_ID_BASE = 100_000, 500_000  # global instance ids: base + 1000 k + i


def object_weights() -> dict[str, float]:
    """Probability of each object kind (sums to 1): `HARD_NEGATIVE_SHARE` and `BROAD_SHARE` split
    equally within their groups, the rest equally among the other kinds."""
    groups = (HARD_NEGATIVES, BROAD_OBJECTS)
    rest = [k for k in OBJECT_KINDS if not any(k in g for g in groups)]
    w = {k: (1.0 - HARD_NEGATIVE_SHARE - BROAD_SHARE) / len(rest) for k in rest}
    for group, share in zip(groups, (HARD_NEGATIVE_SHARE, BROAD_SHARE), strict=True):
        w |= {k: share / len(group) for k in group}
    return {k: w[k] for k in OBJECT_KINDS}


def mixture() -> dict[tuple[str, str], float]:
    """Probability of every (kind, type), e.g. ("object", "rake"); sums to 1."""
    out = {("object", k): OBJECT_FRACTION * p for k, p in object_weights().items()}
    total = sum(BODY_WEIGHTS.values())
    out |= {("body", k): (1 - OBJECT_FRACTION) * p / total for k, p in BODY_WEIGHTS.items()}
    return out


def instance_id_for(kind: str, name: str, index: int) -> int:
    """Global instance id of the ``index``-th instance of ``name`` (unique across all types)."""
    if not 0 <= index < MAX_INSTANCES_PER_KIND:
        raise ConfigError(f"instance index {index} out of range; allowed [0, 999]")
    if kind == "object":
        return OBJECT_ID_BASE + MAX_INSTANCES_PER_KIND * OBJECT_KINDS.index(name) + index
    return BODY_ID_BASE + MAX_INSTANCES_PER_KIND * BODY_KINDS.index(name) + index


def sample_nonhand(
    rng: np.random.Generator, instances_per_kind: int = 20
) -> tuple[ContactorSpec, PressPlan]:
    """A non-hand contactor and its press, drawn from `mixture` and the instance pools.

    The press mode ("pressed", "leaning", ...) is added to the spec's description as "press".
    """
    if not 1 <= instances_per_kind <= MAX_INSTANCES_PER_KIND:
        raise ConfigError(f"instances_per_kind={instances_per_kind}; allowed [1, 1000]")
    keys, p = _mixture_table()
    kind, name = keys[int(rng.choice(len(keys), p=p))]
    iid = instance_id_for(kind, name, int(rng.integers(instances_per_kind)))
    return pressed_instance(kind, name, iid, rng)


@lru_cache(maxsize=1)
def _mixture_table() -> tuple[list[tuple[str, str]], np.ndarray]:
    table = mixture()
    p = np.array(list(table.values()))
    return list(table), p / p.sum()


@lru_cache(maxsize=512)
def instance_spec(kind: str, name: str, instance_id: int) -> ContactorSpec:
    """Instance ``instance_id`` of type ``name``: its geometry depends on the id alone, so it is
    built once per worker (`build_object` and `build_body_part` draw nothing else)."""
    build = build_object if kind == "object" else build_body_part
    return build(name, None, instance_id)


def pressed_instance(
    kind: str, name: str, instance_id: int, rng: np.random.Generator
) -> tuple[ContactorSpec, PressPlan]:
    """Instance ``instance_id`` of type ``name`` ("object" or "body" ``kind``) and a press drawn
    from ``rng``; the press mode is recorded in the description as "press"."""
    spec = instance_spec(kind, name, instance_id)
    press = object_press if kind == "object" else body_press
    mode, plan = press(spec, rng)
    return replace(spec, description=spec.description | {"press": mode}), plan
