"""The contacts of a dataset whose samples hold several (generation option ``[mix]``, field
``n_contacts``): samples by number of contacts and by pair of contactor kinds, and the separate
contacts the tactile image shows (``instance_image``) against those pressing.

    with open_dataset("out/mix") as ds:
        groups = contact_groups(ds)     # None: one contact per sample (no n_contacts)
    g = groups[1]      # all samples of 2 contacts: g.n, g.seen.value (mean), g.fewer.value (%)

A contact "seen" is a distinct non-zero value of the sample's ``instance_image`` (made like the
label image, `tactile.images.labels.label_image`, over contacts): a contact with no taxel above the
active threshold, a print too small for the image's erosion, or one outweighed by the other
contact wherever it presses leaves none, so a 2-contact sample may show 1.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np

from tactile.prints.figures import Estimate
from tactile.prints.measures import CHUNK, bootstrap_mean

KINDS = {"hand": "hand", "object": "object", "body": "body part"}  # kind -> name, in this order
SAME, TWO = "hand + hand, same person", "hand + hand, two people"
ALL = "all"  # the name of the group of every sample of one number of contacts


@dataclass(frozen=True)
class ContactGroup:
    """Samples of one number of contacts (name `ALL`) or of one set of contactor kinds of it
    (`pair_name`): ``n`` samples, ``share`` % of the dataset's, ``contacts`` pressing in each,
    ``seen`` the mean contacts shown by ``instance_image`` and ``fewer`` the % of samples that
    show fewer than press (Estimates, 95 % bootstrap over samples; None without
    ``instance_image``)."""

    name: str
    n: int
    share: float
    contacts: int
    seen: Estimate | None
    fewer: Estimate | None


def pair_name(contactor: str | bytes | None) -> str:
    """The contactors of a sample by their kinds (hand, object, body part, in this order)
    joined by " + ", from its JSON ``contactor`` (a list of descriptions, or one); two hands by
    their ``subject``: `SAME` or `TWO` ("hand + hand" without subjects). "unknown" when the JSON
    cannot be read."""
    try:
        desc = json.loads(contactor.decode() if isinstance(contactor, bytes) else contactor)
    except (TypeError, ValueError, AttributeError):
        return "unknown"
    desc = desc if isinstance(desc, list) else [desc]
    if not all(isinstance(d, dict) for d in desc):
        return "unknown"
    kinds = [str(d.get("kind", "unknown")) for d in desc]
    if kinds == ["hand", "hand"]:
        first, second = (d.get("subject") for d in desc)
        if first is None or second is None:
            return "hand + hand"
        return SAME if first == second else TWO
    order = list(KINDS)
    kinds.sort(key=lambda k: order.index(k) if k in order else len(order))
    return " + ".join(KINDS.get(k, k) for k in kinds)


def contacts_seen(images: np.ndarray) -> np.ndarray:
    """(S,) int64: distinct non-zero values of each (H, W) image of ``images`` (S, H, W)."""
    top = int(images.max(initial=0))
    seen = np.zeros(len(images), np.int64)
    for v in range(1, top + 1):
        seen += (images == v).any(axis=(1, 2))
    return seen


def group_figures(
    names: list[str], n_contacts: np.ndarray, seen: np.ndarray | None, seed: int = 0
) -> list[ContactGroup]:
    """The groups of samples: each number of contacts (`ALL`), then each set of contactor kinds
    (``names`` (S,), e.g. `pair_name`'s) by number of contacts and the order of `KINDS`;
    ``seen`` (S,) the contacts each image shows, or None."""
    names, n_contacts = np.asarray(names, dtype=str), np.asarray(n_contacts, np.int64)
    masks = [(ALL, n_contacts == k) for k in np.unique(n_contacts)]
    pairs = sorted(
        set(zip(n_contacts.tolist(), names.tolist(), strict=True)),
        key=lambda p: (p[0], _rank(p[1]), p[1]),
    )
    masks += [(name, (n_contacts == k) & (names == name)) for k, name in pairs]
    return [_group(name, m, n_contacts, seen, seed) for name, m in masks]


def _rank(name: str) -> tuple[int, ...]:
    order = [*KINDS.values(), "unknown"]
    parts = name.split(",")[0].split(" + ")
    return tuple(order.index(p) if p in order else len(order) for p in parts)


def _group(name, mask, n_contacts, seen, seed) -> ContactGroup:
    n = int(mask.sum())
    contacts = int(n_contacts[mask][0])
    share = 100.0 * n / len(mask)
    if seen is None:
        return ContactGroup(name, n, share, contacts, None, None)
    shown = seen[mask].astype(float)
    fewer = 100 * np.asarray(bootstrap_mean(shown < n_contacts[mask], seed=seed))
    return ContactGroup(
        name,
        n,
        share,
        contacts,
        Estimate(*bootstrap_mean(shown, seed=seed), n),
        Estimate(*fewer.tolist(), n),
    )


def contact_groups(ds, seed: int = 0) -> list[ContactGroup] | None:
    """`group_figures` of the dataset ``ds`` (a `tactile.dataset.DatasetReader`): names from its
    ``contactor`` JSON ("unknown" without it), contacts seen from its ``instance_image`` (read
    `CHUNK` samples at a time); None without ``n_contacts``."""
    fields = set(ds.fields)
    if "n_contacts" not in fields:
        return None
    n = len(ds)
    text = ds["contactor"][:] if "contactor" in fields else [None] * n
    seen = None
    if "instance_image" in fields:
        images = ds["instance_image"]
        seen = np.concatenate(
            [contacts_seen(images[s : min(s + CHUNK, n)]) for s in range(0, n, CHUNK)]
        )
    return group_figures([pair_name(t) for t in text], ds["n_contacts"][:], seen, seed)
