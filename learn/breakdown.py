"""Scores by contact size, contactor, action and hand parts in contact: where a hand /
non-hand classifier or a hand-part segmenter fails.

A touch that presses a handful of taxels carries little shape; the paper reports one accuracy
over all images. ``handskin evaluate`` adds, for a handskin dataset, the accuracy of each true
class within bins of the number of active taxels (pressure above the dataset's active
threshold) and within bins of the press force (the dataset's ``force_n``, newtons), and the
accuracy on each kind of contactor (``kind: type`` from the dataset's ``contactor`` JSON, e.g.
``object: rake``), so a user sees which contacts cost the accuracy;
and for the hand samples, the accuracy by the hand parts that press (a palm alone leaves one
round print) and by action. For a segmenter it adds pixel accuracy and mIoU of each group of
test images: by contactor (right or left hand), by the dataset's ``action``, by press force and
by how many hand parts touch (from the label image): finger identity is easy to see on a
whole-hand print and not on three fingertips.
Finally it lists a classifier's errors, most confident first (a segmenter's worst images are
`learn.worst`'s).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from itertools import pairwise
from pathlib import Path

import numpy as np

#: Lower edges of the active-taxel bins (count); the last bin is open.
EDGES: tuple[int, ...] = (0, 10, 20, 40, 80)

#: Lower edges of the press-force bins (newtons); the last bin is open. A hand pressing under
#: 10 N leaves a print of a few taxels.
FORCE_EDGES_N: tuple[float, ...] = (0, 5, 10, 20, 40)


def accuracy_by_bins(
    pred: np.ndarray,
    truth: np.ndarray,
    values: np.ndarray,
    class_names: Sequence[str],
    edges: Sequence[float],
) -> list[dict[str, object]]:
    """Per bin ``[lo, hi)`` of ``values``: samples and accuracy (fraction) of each true class.

    pred, truth : (S,) int class ids; values : (S,) a number per sample (active taxels, press
    force in N); edges : increasing lower bin edges, the last bin open. A sample below the first
    edge (or NaN) is in no bin. Returns one dict per bin: ``{"lo", "hi" (None: open), "n",
    "per_class": {name: {"n", "accuracy" (None when the bin has no sample of the class)}}}``.
    """
    pred, truth, values = (np.asarray(a).ravel() for a in (pred, truth, values))
    if not len(pred) == len(truth) == len(values):
        raise ValueError(
            f"pred, truth and values differ in length: {len(pred)}, {len(truth)}, {len(values)}"
        )
    rows = []
    for lo, hi in pairwise([*edges, None]):
        in_bin = (values >= lo) & (True if hi is None else values < hi)
        per_class = {}
        for c, name in enumerate(class_names):
            m = in_bin & (truth == c)
            acc = float(np.mean(pred[m] == c)) if m.any() else None
            per_class[name] = {"n": int(m.sum()), "accuracy": acc}
        rows.append(
            {
                "lo": plain_scalar(lo),
                "hi": None if hi is None else plain_scalar(hi),
                "n": int(in_bin.sum()),
                "per_class": per_class,
            }
        )
    return rows


def accuracy_by_active_taxels(
    pred: np.ndarray,
    truth: np.ndarray,
    n_active: np.ndarray,
    class_names: Sequence[str],
    edges: Sequence[int] = EDGES,
) -> list[dict[str, object]]:
    """:func:`accuracy_by_bins` of the active-taxel counts ``n_active`` (S,) int."""
    return accuracy_by_bins(pred, truth, n_active, class_names, edges)


def rows_in_order(reader, field: str, indices: np.ndarray) -> np.ndarray:
    """Field ``field`` of samples ``indices`` (S,) of an open `DatasetReader`, in the order of
    ``indices`` (h5py reads a list of rows in increasing order only); (S, ...)."""
    order = np.argsort(indices)
    raw = reader[field][np.asarray(indices)[order]]
    out = np.empty_like(raw)
    out[order] = raw
    return out


def press_forces_n(data_path: str | Path, indices: np.ndarray) -> np.ndarray | None:
    """The press force (N, the dataset's ``force_n``: total normal force at the sampled frame)
    of samples ``indices`` (S,) of a handskin dataset, (S,) float64; None without the field
    (ingested recordings)."""
    from tactile.dataset.reader import DatasetReader

    with DatasetReader(data_path) as reader:
        if "force_n" not in reader.fields:
            return None
        return rows_in_order(reader, "force_n", indices).astype(np.float64)


def bin_labels(
    values: np.ndarray, edges: Sequence[float], unit: str
) -> tuple[list[str], list[str]]:
    """(label of each of ``values`` (S,), the labels in bin order): ``"5–10 N"`` for ``[5, 10)``,
    ``"40+ N"`` for the open last bin, ``"unknown"`` below the first edge or NaN."""
    names = [
        f"{lo:g}+ {unit}" if hi is None else f"{lo:g}–{hi:g} {unit}"
        for lo, hi in pairwise([*edges, None])
    ]
    k = np.searchsorted(np.asarray(edges, float), np.asarray(values, float), side="right") - 1
    labels = [
        names[j] if j >= 0 and np.isfinite(v) else "unknown"
        for j, v in zip(k.tolist(), np.asarray(values, float).tolist(), strict=True)
    ]
    return labels, names


def active_taxel_counts(data_path: str | Path, indices: np.ndarray) -> np.ndarray:
    """Active taxels (count, pressure above the dataset's active threshold) of samples
    ``indices`` (S,) of a handskin dataset; (S,) int64."""
    from learn.predict import active_threshold_pa
    from tactile.dataset.reader import DatasetReader

    with DatasetReader(data_path) as reader:
        p = rows_in_order(reader, "pressure_pa", indices)
        return (p > active_threshold_pa(reader)).sum(axis=1).astype(np.int64)


def breakdown_markdown(
    rows: list[dict], title: str = "active taxels", unit: str | None = None
) -> list[str]:
    """A markdown table of :func:`accuracy_by_bins` (accuracy in %), first column ``title``:
    count bins ``10–19`` (``unit`` None), or half-open bins of a measure ``5–10 N``."""
    names = list(rows[0]["per_class"]) if rows else []
    head = f"| {title} | " + " | ".join(f"{n}: samples | {n}: accuracy %" for n in names)
    lines = [head + " |", "|---|" + "---|---|" * len(names)]
    for r in rows:
        if unit is None:
            span = f"{r['lo']}+" if r["hi"] is None else f"{r['lo']}–{r['hi'] - 1}"
        else:
            span = f"{r['lo']:g}+ {unit}" if r["hi"] is None else f"{r['lo']:g}–{r['hi']:g} {unit}"
        cells = []
        for n in names:
            c = r["per_class"][n]
            cells += [str(c["n"]), "–" if c["accuracy"] is None else f"{100 * c['accuracy']:.1f}"]
        lines.append(f"| {span} | " + " | ".join(cells) + " |")
    return lines


def accuracy_by_group(
    pred: np.ndarray, truth: np.ndarray, groups: Sequence[str]
) -> list[dict[str, object]]:
    """Samples, errors and accuracy (fraction) of every group, least accurate first (ties by name).

    pred, truth : (S,) int class ids; groups : (S,) str group of each sample.
    """
    pred, truth, groups = np.asarray(pred).ravel(), np.asarray(truth).ravel(), np.asarray(groups)
    if not len(pred) == len(truth) == len(groups):
        raise ValueError(
            f"pred, truth and groups differ in length: {len(pred)}, {len(truth)}, {len(groups)}"
        )
    rows = []
    for g in np.unique(groups):
        m = groups == g
        ok = int(np.sum(pred[m] == truth[m]))
        rows.append(
            {
                "group": str(g),
                "n": int(m.sum()),
                "errors": int(m.sum()) - ok,
                "accuracy": ok / int(m.sum()),
            }
        )
    return sorted(rows, key=lambda r: (r["accuracy"], r["group"]))


def contactor_types(data_path: str | Path, indices: np.ndarray) -> list[str]:
    """``"<kind>: <type>"`` of samples ``indices`` (S,) from the dataset's ``contactor`` JSON
    (``"unknown"`` where the field or its keys are missing, e.g. ingested recordings)."""
    from tactile.dataset.reader import DatasetReader

    with DatasetReader(data_path) as reader:
        if "contactor" not in reader.fields:
            return ["unknown"] * len(indices)
        raw = rows_in_order(reader, "contactor", indices)
    out = []
    for text in raw:
        try:
            c = json.loads(text.decode() if isinstance(text, bytes) else text)
            out.append(f"{c['kind']}: {c.get('type', c.get('name'))}")
        except (ValueError, KeyError, TypeError):
            out.append("unknown")
    return out


#: Groups of hand samples by the hand parts that press (`hand_parts_group`), in table order.
HAND_PART_GROUPS: tuple[str, ...] = (
    "no part",
    "palm only",
    "one finger",
    "palm + one finger",
    "two fingers",
    "3 parts",
    "4 parts",
    "5 parts",
    "6 parts",
)


def hand_parts_group(parts: set[int] | frozenset[int], palm: int = 6) -> str:
    """The `HAND_PART_GROUPS` name of a hand sample whose active taxels carry the hand-part
    class ids ``parts`` (1..6, ``palm`` the palm's; 0 "none" ignored): a palm alone or one
    finger carries little of a hand's shape, a print of several parts more."""
    parts = set(parts) - {0}
    k, has_palm = len(parts), palm in parts
    if k == 0:
        return "no part"
    if k == 1:
        return "palm only" if has_palm else "one finger"
    if k == 2:
        return "palm + one finger" if has_palm else "two fingers"
    return f"{k} parts"


def hand_parts_groups(data_path: str | Path, indices: np.ndarray) -> list[str | None]:
    """`hand_parts_group` of each of samples ``indices`` (S,) of a handskin dataset from the
    ``taxel_label`` of its active taxels (pressure above the dataset's active threshold);
    None for a non-hand sample (all None when the dataset has no ``is_hand``), ``"unknown"``
    for a hand when the dataset has no ``taxel_label``."""
    from learn.predict import active_threshold_pa
    from tactile import CLASS_NAMES
    from tactile.dataset.reader import DatasetReader

    out: list[str | None] = [None] * len(indices)
    with DatasetReader(data_path) as reader:
        if "is_hand" not in reader.fields:
            return out
        order = np.argsort(indices)
        rows = np.asarray(indices)[order]
        hand = reader["is_hand"][rows]
        labels = active = None
        if "taxel_label" in reader.fields:
            labels = reader["taxel_label"][rows]
            active = reader.pressure_pa[rows] > active_threshold_pa(reader)
    palm = CLASS_NAMES.index("palm")
    for j, pos in enumerate(order):
        if hand[j]:
            out[pos] = (
                "unknown"
                if labels is None
                else hand_parts_group(set(labels[j][active[j]].tolist()), palm)
            )
    return out


def hands_by_group(
    pred: np.ndarray,
    truth: np.ndarray,
    groups: Sequence[str | None],
    order: Sequence[str] | None = None,
) -> list[dict[str, object]]:
    """`accuracy_by_group` over the samples whose group is not None (hand samples); rows in
    ``order`` (groups not in it last) or, without ``order``, least accurate first."""
    keep = np.flatnonzero([g is not None for g in groups])
    rows = accuracy_by_group(
        np.asarray(pred).ravel()[keep], np.asarray(truth).ravel()[keep], [groups[k] for k in keep]
    )
    if order is not None:
        rank = {g: i for i, g in enumerate(order)}
        rows.sort(key=lambda r: (rank.get(r["group"], len(rank)), r["group"]))
    return rows


def group_markdown(rows: list[dict], title: str = "contactor") -> list[str]:
    """A markdown table of :func:`accuracy_by_group` (accuracy in %), first column ``title``."""
    lines = [f"| {title} | samples | errors | accuracy % |", "|---|---|---|---|"]
    lines += [
        f"| {r['group']} | {r['n']} | {r['errors']} | {100 * r['accuracy']:.1f} |" for r in rows
    ]
    return lines


def segmentation_by_group(
    pred: np.ndarray,
    truth: np.ndarray,
    groups: Sequence[str],
    num_classes: int,
    by_name: bool = False,
    order: Sequence[str] | None = None,
) -> list[dict[str, object]]:
    """Per group: samples, pixel accuracy and mIoU (fractions) of the group's pooled confusion
    matrix (Long et al.; classes absent from the group's ground truth skipped), lowest mIoU
    first (``by_name``: in the groups' sorted order; ``order``: in that order, other groups
    last).

    pred, truth : (S, h, w) int class ids; groups : (S,) str group of each image.
    """
    import torch

    from learn import metrics as M

    groups = np.asarray(groups)
    if not len(pred) == len(truth) == len(groups):
        raise ValueError(
            f"pred, truth and groups differ in length: {len(pred)}, {len(truth)}, {len(groups)}"
        )
    pred, truth, rows = torch.as_tensor(pred), torch.as_tensor(truth), []
    for g in np.unique(groups):
        m = torch.from_numpy(np.flatnonzero(groups == g))
        cm = M.confusion_matrix(truth[m], pred[m], num_classes)
        rows.append(
            {
                "group": str(g),
                "n": len(m),
                "pixel_accuracy": M.accuracy(cm),
                "mean_iou": M.mean_iou(cm),
            }
        )
    if order is not None:
        rank = {g: i for i, g in enumerate(order)}
        return sorted(rows, key=lambda r: (rank.get(r["group"], len(rank)), r["group"]))
    return rows if by_name else sorted(rows, key=lambda r: (r["mean_iou"], r["group"]))


def parts_in_contact(truth: np.ndarray, num_classes: int) -> np.ndarray:
    """(S,) int: how many of classes 1 .. num_classes - 1 (hand parts) each label image of
    ``truth`` (S, h, w) holds."""
    flat = np.asarray(truth).reshape(len(truth), -1)
    return np.stack([(flat == c).any(1) for c in range(1, num_classes)], 1).sum(1)


def action_names(data_path: str | Path, indices: np.ndarray) -> list[str]:
    """The ``action`` name (from ``attrs["actions"]``) of samples ``indices`` (S,) of a handskin
    dataset; ``"none"`` for -1 and ``"unknown"`` when the field or the names are missing."""
    from tactile.dataset.reader import DatasetReader

    with DatasetReader(data_path) as reader:
        names = list(reader.attrs.get("actions", []))
        if "action" not in reader.fields or not names:
            return ["unknown"] * len(indices)
        raw = rows_in_order(reader, "action", indices)
    return ["none" if a < 0 else names[a] if a < len(names) else "unknown" for a in raw]


def segmentation_group_markdown(rows: list[dict], title: str) -> list[str]:
    """A markdown table of :func:`segmentation_by_group` (scores in %), first column ``title``."""
    lines = [f"| {title} | images | pixel accuracy % | mIoU % |", "|---|---|---|---|"]
    lines += [
        f"| {r['group']} | {r['n']} | {100 * r['pixel_accuracy']:.1f} | {100 * r['mean_iou']:.1f} |"
        for r in rows
    ]
    return lines


def misclassified(
    pred: np.ndarray,
    truth: np.ndarray,
    confidence: np.ndarray,
    indices: Sequence[int],
    class_names: Sequence[str],
    about: dict[str, Sequence] | None = None,
    confidence_name: str = "probability",
) -> list[dict[str, object]]:
    """The wrongly classified samples, most confident first: where a classifier is sure and
    wrong. pred, truth : (S,) int class ids; confidence : (S,) how sure the classifier was of
    its prediction, larger surer (a network's softmax probability 0..1, an SVM's margin);
    indices : (S,) dataset sample indices; ``about`` : named (S,) sequences copied into each
    record (e.g. contactor, active taxels).

    Returns ``{"index", "true", "predicted", confidence_name, **about}`` dicts.
    """
    pred, truth, confidence = (np.asarray(a).ravel() for a in (pred, truth, confidence))
    wrong = np.flatnonzero(pred != truth)
    wrong = wrong[np.argsort(-confidence[wrong], kind="stable")]
    about = about or {}
    return [
        {
            "index": int(indices[k]),
            "true": class_names[truth[k]],
            "predicted": class_names[pred[k]],
            confidence_name: float(confidence[k]),
            **{name: plain_scalar(values[k]) for name, values in about.items()},
        }
        for k in wrong
    ]


def classifier_breakdown(
    data_path: str | Path,
    indices: np.ndarray,
    pred: np.ndarray,
    truth: np.ndarray,
    confidence: np.ndarray,
    class_names: Sequence[str],
    confidence_name: str = "probability",
) -> dict[str, object]:
    """A classifier's report fields on a handskin dataset's test samples ``indices`` (S,):
    ``by_active_taxels``, ``by_force`` (press force bins `FORCE_EDGES_N`, N; None without the
    dataset's ``force_n``), ``by_contactor``, the hand samples' accuracy by the hand parts that
    press (``hands_by_parts``, in `HAND_PART_GROUPS` order) and by action (``hands_by_action``,
    least accurate first), and ``errors`` (most confident first; see `misclassified` for
    ``confidence`` (S,) and ``confidence_name``)."""
    n_active = active_taxel_counts(data_path, indices)
    contactors = contactor_types(data_path, indices)
    actions = action_names(data_path, indices)
    parts = hand_parts_groups(data_path, indices)
    hand_actions = [a if p is not None else None for a, p in zip(actions, parts, strict=True)]
    forces = press_forces_n(data_path, indices)
    return {
        "by_active_taxels": accuracy_by_active_taxels(pred, truth, n_active, class_names),
        "by_force": (
            None
            if forces is None
            else accuracy_by_bins(pred, truth, forces, class_names, FORCE_EDGES_N)
        ),
        "by_contactor": accuracy_by_group(pred, truth, contactors),
        "hands_by_parts": hands_by_group(pred, truth, parts, HAND_PART_GROUPS),
        "hands_by_action": hands_by_group(pred, truth, hand_actions),
        "errors": misclassified(
            pred,
            truth,
            confidence,
            indices,
            class_names,
            {
                "contactor": contactors,
                "active taxels": n_active.tolist(),
                "action": actions,
                "hand parts": parts,
            },
            confidence_name,
        ),
    }


def segmenter_breakdown(
    data_path: str | Path,
    indices: np.ndarray,
    pred: np.ndarray,
    truth: np.ndarray,
    num_classes: int,
    actions: Sequence[str],
    parts: Sequence[str],
) -> dict[str, list[dict[str, object]]]:
    """A segmenter's scores (`segmentation_by_group`) on a handskin dataset's test images
    ``indices`` (S,) — pred, truth (S, h, w) class ids — by contactor, by action (``actions``
    (S,), `action_names`), by hand parts touching (``parts`` (S,), counts as text) and, when the
    dataset has ``force_n``, by press force (bins `FORCE_EDGES_N`, N, in order)."""
    out = {
        "contactor": segmentation_by_group(
            pred, truth, contactor_types(data_path, indices), num_classes
        ),
        "action": segmentation_by_group(pred, truth, actions, num_classes),
        "hand parts touching": segmentation_by_group(pred, truth, parts, num_classes, by_name=True),
    }
    forces = press_forces_n(data_path, indices)
    if forces is not None:
        labels, order = bin_labels(forces, FORCE_EDGES_N, "N")
        out["press force"] = segmentation_by_group(pred, truth, labels, num_classes, order=order)
    return out


def svm_margin(scores: np.ndarray) -> np.ndarray:
    """How sure a linear SVM is of its prediction, (S,): ``|score|`` of a two-class SVM's
    (S,) scores, the top score minus the runner-up of (S, C) one-vs-rest scores."""
    scores = np.asarray(scores, np.float64)
    if scores.ndim == 1:
        return np.abs(scores)
    top2 = np.sort(scores, axis=1)[:, -2:]
    return top2[:, 1] - top2[:, 0]


def plain_scalar(v: object) -> object:
    """A numpy scalar as the Python number it holds (for JSON); anything else as it is."""
    return v.item() if isinstance(v, np.generic) else v
