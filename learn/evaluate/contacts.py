"""Scores by number of contacts, for datasets whose samples hold several contacts (generation
option ``[mix]``, field ``n_contacts``): the classifiers' accuracy on 1 and on 2 contacts with
its 95 % interval, and the segmenters' mIoU on the hand samples of 1 and of 2 contacts (2: the
"multi-contact hands", a hand beside a second hand, an object or a body part).

    contacts = split_contacts(Path("out/mix"), "classify", (68, 100))   # None: one contact each
    row |= contact_scores(res.predictions, test.y, contacts, "classify", 2)
    lines = contacts_section(rows, labels)                              # [] without contacts

Rows of the test split are those of `learn.data.load.open_split` (the dataset's test split in
its stored order; the segmenters' hand samples of it), as ``handskin evaluate`` reads them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from learn import metrics as M
from learn.data.load import is_dataset, open_split
from tactile.errors import DataError
from tactile.prints.measures import bootstrap_mean

BOOT_SEED = 0  # seed of the accuracy's bootstrap interval
KEY = "by_contacts"  # the report row's key
HAND, NO_HAND = "hand", "no hand"  # classifier groups "<k> hand": a hand among the k contacts


@dataclass(frozen=True)
class SplitContacts:
    """Per test row (`open_split`'s order): contactors pressing ``n`` (S,) int64 (1 or 2) and
    whether a hand is among them, ``hand`` (S,) bool."""

    n: np.ndarray
    hand: np.ndarray


def split_contacts(
    data_path: Path, task: str, size: tuple[int, int], canvas_mm: tuple[float, float] | None = None
) -> SplitContacts | None:
    """The contacts of each test row of ``data_path`` as ``task``'s networks read it; None for
    data without ``n_contacts`` (an image folder, a dataset of one contact per sample)."""
    if task not in ("classify", "segment") or not is_dataset(data_path):
        return None
    ds = open_split(data_path, "test", task, tuple(size), None, 0, canvas_mm)
    with ds.reader as r:
        if "n_contacts" not in r.fields:
            return None
        n, hand = r.n_contacts[:], r.is_hand[:]
    rows = np.asarray(ds.indices)
    return SplitContacts(n[rows].astype(np.int64), hand[rows] == 1)


def contact_scores(
    pred: torch.Tensor, y: torch.Tensor, contacts: SplitContacts, task: str, num_classes: int
) -> dict:
    """``{KEY: {"1": ..., "2": ...}}`` of predictions ``pred`` against ``y`` ((S,) or (S, h, w)),
    per number of contacts present: classify, ``n`` samples, ``accuracy`` and its 95 %
    percentile bootstrap interval ``low``, ``high`` over samples (fractions), also for the
    samples of a hand among them (``"<k> hand"``) and of none (``"<k> no hand"``); segment,
    ``n`` hand samples and their confusion matrix ``cm`` (C, C) (rows true)."""
    if len(pred) != len(contacts.n) or len(y) != len(contacts.n):
        raise DataError(
            f"{len(contacts.n)} test rows have contacts, {len(y)} were scored: the test split "
            "changed while it was scored. Fix: evaluate again once the dataset is written"
        )
    out = {}
    for k in np.unique(contacts.n).tolist():
        if task == "classify":
            count, hand = contacts.n == k, contacts.hand
            groups = {str(k): count, f"{k} {HAND}": count & hand, f"{k} {NO_HAND}": count & ~hand}
            for key, rows in groups.items():
                if rows.any():
                    sel = torch.from_numpy(rows)
                    correct = (pred[sel] == y[sel]).numpy().astype(float)
                    acc, low, high = bootstrap_mean(correct, seed=BOOT_SEED)
                    out[key] = {"n": len(correct), "accuracy": acc, "low": low, "high": high}
        else:
            sel = torch.from_numpy((contacts.n == k) & contacts.hand)
            cm = M.confusion_matrix(y[sel], pred[sel], num_classes)
            out[str(k)] = {"n": int(sel.sum()), "cm": cm.tolist()}
    return {KEY: out}


def _pct(v: float) -> str:
    return "–" if v is None or np.isnan(v) else f"{100 * v:.2f}"


def _contacts(k: str, task: str) -> str:
    if task == "classify":
        n, _, group = k.partition(" ")
        words = "1 contact" if n == "1" else f"{n} contacts"
        among = "a hand" if n == "1" else "a hand among them"
        return words + {"": "", HAND: f", {among}", NO_HAND: ", no hand"}[group]
    return "1 (a hand)" if k == "1" else f"{k}, a hand among them"


def contacts_section(rows: list[dict], labels: list[str]) -> list[str]:
    """The report's lines on the rows scored by number of contacts (none: no lines)."""
    mine = [(r, lab) for r, lab in zip(rows, labels, strict=True) if r.get(KEY)]
    if not mine:
        return []
    clf = [(r, lab) for r, lab in mine if r["task"] == "classify"]
    seg = [(r, lab) for r, lab in mine if r["task"] == "segment"]
    out = [
        "## By number of contacts",
        "",
        "The test split by the contactors pressing at once (`n_contacts`). Classifiers: every "
        "test sample, accuracy with its 95 % percentile bootstrap interval over the samples "
        f"(seed {BOOT_SEED}), then those with a hand among the contacts and those without. "
        "Segmenters: the hand samples they are scored on, 2 contacts being "
        "the multi-contact hands (a hand beside a second hand, an object or a body part); "
        "hand-pixel mIoU as in the table on the hand's pixels.",
        "",
    ]
    if clf:
        out += [
            "| method | contacts | test samples | accuracy % | 95 % interval |",
            "|---|---|---|---|---|",
        ]
        for r, lab in clf:
            for k, s in r[KEY].items():
                span = f"[{_pct(s['low'])}, {_pct(s['high'])}]"
                cells = [lab, _contacts(k, "classify"), str(s["n"]), _pct(s["accuracy"]), span]
                out.append("| " + " | ".join(cells) + " |")
        out.append("")
    if seg:
        out += [
            "| method | contacts | hand test samples | mIoU % | hand-pixel mIoU % |",
            "|---|---|---|---|---|",
        ]
        for r, lab in seg:
            for k, s in r[KEY].items():
                cm = torch.tensor(s["cm"])
                miou = M.mean_iou(cm) if s["n"] else float("nan")
                hand = M.mean_iou(M.without_true_class(cm)) if s["n"] else float("nan")
                cells = [lab, _contacts(k, "segment"), str(s["n"]), _pct(miou), _pct(hand)]
                out.append("| " + " | ".join(cells) + " |")
        out.append("")
    return out
