"""Networks trained on simulation, scored on real box-labelled prints (`tactile.dataset.boxes`):
what ``handskin evaluate`` reports when its data is a box folder.

    rows = evaluate_real("data/real1", ["runs/handsnet/best.pt", "runs/segnet/best.pt"])
    write_real_report(rows, "reports/real/fold1.md", header)      # and fold1.json, fold1.png

- A classifier: its **hand recall** on the real prints (every one is a hand), beside its
  **non-hand specificity** on the test split of a simulated dataset (``negatives``; by default
  the dataset it was trained on), so that a classifier answering "hand" always cannot score
  (the classical ones, BoVW and VGG16 + SVM: `learn.classical.run.real_hand_scores`).
- A segmenter: **part localisation**. Every contact pixel belongs to the smallest box holding
  it (the rule of the box-derived labels); for every real part box, the segmenter's majority
  class over its pixels is right when it is the box's part (chance about 1 in 6), per part and
  overall. And the **box IoU**: each real box against the tight box around the pixels the
  segmenter gives its part (0 where it gives none), with the share above 0.5. What each part's
  boxes are **taken for** (the majority classes, a confusion table), and the localisation **by
  where the print's fingers point** (`tactile.prints.shapes.DIRECTION`, from its boxes): the
  real folds' hands mostly point one way, and a network fails where simulation put few hands.
- A picture: real prints with their boxes and the predicted parts over them.
"""

from __future__ import annotations

import itertools
import json
from pathlib import Path

import numpy as np
import torch
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from learn.data.folder import HAND_NAMES
from learn.infer.predict import Predictor, load_predictor, segment
from learn.inputs import net_input
from learn.numerics import flushing
from learn.train.checkpoint import load_checkpoint
from tactile.dataset.boxes import BoxFolder, box_members
from tactile.dataset.reader import DatasetReader
from tactile.errors import ConfigError, DataError
from tactile.files import save_figure, write_text_atomic
from tactile.images.labels import CLASS_NAMES, PALETTE
from tactile.prints.shapes import part_layout

PARTS = CLASS_NAMES[1:]
# Bins of `fingers_deg` (palm to fingers, degrees from +rows towards +columns, a left-drawn hand
# mirrored) for the localisation by direction: 45 degrees each, from -180.
DIRECTION_EDGES_DEG = np.arange(-180, 181, 45)
BATCH = 64  # images per forward pass on the simulated negatives


def wilson(k: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """The 95 % Wilson score interval of a share of ``k`` in ``n`` (0..1)."""
    if n == 0:
        return float("nan"), float("nan")
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * np.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def _hand_index(pred: Predictor) -> int:
    if pred.task == "both":
        return HAND_NAMES.index("hand")
    if "hand" not in pred.class_names:
        raise ConfigError(f"the classifier's classes {pred.class_names} have no 'hand'")
    return pred.class_names.index("hand")


@flushing()
def hand_recall(pred: Predictor, folder: BoxFolder) -> dict:
    """How many of the folder's prints (all hands) the classifier calls hand."""
    hand = _hand_index(pred)
    said = []
    for i in range(len(folder)):
        logits = pred.logits(folder[i].image)
        said.append(int((logits[0] if pred.task == "both" else logits).argmax()) == hand)
    k, n = int(sum(said)), len(said)
    return {"hand_recall": k / n, "hand_recall_ci": wilson(k, n), "n_real": n}


def split_non_hands(ds: DatasetReader, name: str | Path) -> np.ndarray:
    """Sorted indices of the non-hands in the test split of ``ds`` (the dataset ``name``);
    DataError when there is none."""
    test = np.sort(np.asarray(ds.splits["test"]))
    test = test[ds.is_hand[:][test] == 0]
    if not len(test):
        raise DataError(f"{name}: its test split holds no non-hand to score")
    return test


@flushing()
def non_hand_specificity(pred: Predictor, negatives: Path) -> dict:
    """How many of the non-hands of ``negatives``' test split the classifier calls non-hand."""
    hand = _hand_index(pred)
    with DatasetReader(negatives) as ds:
        test = split_non_hands(ds, negatives)
        canvas = pred.canvas(ds.map.step_mm)
        right = 0
        for start in range(0, len(test), BATCH):
            task = "segment" if pred.task == "both" else "classify"
            x = net_input(ds.image[test[start : start + BATCH]], pred.input_size, task, canvas)
            with torch.inference_mode():
                out = pred.model(torch.from_numpy(x)[:, None])
            said = (out[0] if pred.task == "both" else out).argmax(1)
            right += int((said != hand).sum())
    n = len(test)
    return {"specificity": right / n, "specificity_ci": wilson(right, n), "n_non_hand": n}


def localise(prediction: np.ndarray, image: np.ndarray, boxes: np.ndarray) -> list[dict]:
    """Per real box of one print: its part, its contact pixels (the smallest-box rule), the
    segmenter's majority class over them (``prediction`` (H, W) classes on the print's grid)
    and the IoU of the box with the tight box of the pixels predicted as its part."""
    members = box_members(image, boxes)
    out = []
    for k, (part, r0, r1, c0, c1) in enumerate(boxes.tolist()):
        pixels = prediction[members == k]
        majority = (
            int(np.bincount(pixels, minlength=len(CLASS_NAMES)).argmax()) if len(pixels) else -1
        )
        rows, cols = np.nonzero(prediction == part)
        iou = 0.0
        if len(rows):
            inter_r = max(0, min(r1, rows.max() + 1) - max(r0, rows.min()))
            inter_c = max(0, min(c1, cols.max() + 1) - max(c0, cols.min()))
            inter = inter_r * inter_c
            union = (r1 - r0) * (c1 - c0) + (np.ptp(rows) + 1) * (np.ptp(cols) + 1) - inter
            iou = inter / union
        out.append({"part": part, "pixels": len(pixels), "majority": majority, "iou": iou})
    return out


@flushing()
def part_localisation(pred: Predictor, folder: BoxFolder) -> tuple[dict, list[np.ndarray]]:
    """Localisation and box IoU of a segmenter on every real box (boxes holding no contact
    pixel of their own are counted apart), and its predictions (H, W) per print."""
    boxes, predictions = [], []
    for i in range(len(folder)):
        p = folder[i]
        prediction = segment(p.image, pred)
        predictions.append(prediction)
        deg = part_layout(p.boxes)["fingers_deg"]
        boxes += [b | {"deg": deg} for b in localise(prediction, p.image, p.boxes)]
    scored = [b for b in boxes if b["pixels"]]
    per_part = {}
    for part in range(1, len(CLASS_NAMES)):
        mine = [b for b in scored if b["part"] == part]
        right = sum(b["majority"] == part for b in mine)
        per_part[CLASS_NAMES[part]] = {
            "boxes": len(mine),
            "localised": right / len(mine) if mine else float("nan"),
            "iou": float(np.mean([b["iou"] for b in mine])) if mine else float("nan"),
        }
    right = sum(b["majority"] == b["part"] for b in scored)
    ious = np.array([b["iou"] for b in scored])
    scores = {
        "localised": right / len(scored) if scored else float("nan"),
        "localised_ci": wilson(right, len(scored)),
        "boxes": len(scored),
        "boxes_without_contact": len(boxes) - len(scored),
        "box_iou": float(ious.mean()) if len(ious) else float("nan"),
        "box_iou_above_half": float((ious > 0.5).mean()) if len(ious) else float("nan"),
        "per_part": per_part,
        "taken_for": taken_for(scored),
        "by_direction": by_direction(scored),
    }
    return scores, predictions


def taken_for(scored: list[dict]) -> dict[str, list[int]]:
    """Per part: how many of its boxes had each class (`CLASS_NAMES`, background first) as
    their majority."""
    out = {}
    for part in range(1, len(CLASS_NAMES)):
        said = [b["majority"] for b in scored if b["part"] == part]
        out[CLASS_NAMES[part]] = np.bincount(said, minlength=len(CLASS_NAMES)).tolist()
    return out


def by_direction(scored: list[dict]) -> list[dict]:
    """Localisation of the boxes of prints whose fingers point into each bin of
    `DIRECTION_EDGES_DEG` (``fingers_deg`` lies in [-180, 180)), then of prints without a
    direction (no palm, thumb or finger boxed)."""
    deg = np.array([b["deg"] for b in scored], float)
    right = np.array([b["majority"] == b["part"] for b in scored], bool)
    edges = DIRECTION_EDGES_DEG
    bins = [(lo, hi, (deg >= lo) & (deg < hi)) for lo, hi in itertools.pairwise(edges.tolist())]
    bins.append((None, None, np.isnan(deg)))
    return [
        {"from_deg": lo, "to_deg": hi, "boxes": int(m.sum()), "localised": _share(right, m)}
        for lo, hi, m in bins
    ]


def _share(right: np.ndarray, mask: np.ndarray) -> float:
    return float(right[mask].mean()) if mask.any() else float("nan")


def evaluate_real(
    folder: str | Path,
    checkpoints: list[str | Path],
    negatives: str | Path | None = None,
) -> tuple[list[dict], list[np.ndarray] | None]:
    """A row per checkpoint (classifier or segmenter) scored on the box folder ``folder``, and
    the last segmenter's predictions (for `real_picture`). ``negatives``: the simulated dataset
    whose test non-hands a classifier is scored on (default: the one it was trained on)."""
    prints = BoxFolder.open(folder)
    rows, predictions = [], None
    for path in checkpoints:
        pred = load_predictor(path)
        row = {"checkpoint": str(path), "task": pred.task, "folder": str(folder)}
        row["labels_from"] = "boxes"
        if pred.task in ("classify", "both"):
            neg = negatives or trained_on(path)
            row |= hand_recall(pred, prints) | {"negatives": str(neg)}
            row |= non_hand_specificity(pred, Path(neg))
        if pred.task in ("segment", "both"):
            scores, predictions = part_localisation(pred, prints)
            row |= scores
        if pred.task not in ("classify", "segment", "both"):
            raise ConfigError(f"{path}: a '{pred.task}' network; give a classifier or segmenter")
        rows.append(row)
    return rows, predictions


def trained_on(path: str | Path, data: str | None = None) -> Path:
    """The simulated dataset a checkpoint was trained on (``data``: that path, when the caller
    has read it already), where it gives the non-hands a classifier's specificity is scored on."""
    data = data or (load_checkpoint(path).get("data") or {}).get("path")
    if not data or not Path(data).exists():
        raise DataError(
            f"{path}: the dataset it was trained on ({data}) is not here to give simulated "
            "non-hands. Fix: --negatives DATASET (a simulated dataset with non-hands)"
        )
    return Path(data)


def _pct(v: float) -> str:
    return "–" if v != v else f"{100 * v:.1f}"


def real_markdown(rows: list[dict]) -> list[str]:
    """The report's tables: classifiers, then segmenters (overall and per part)."""
    lines = []
    clf = [r for r in rows if r["task"] in ("classify", "both")]
    seg = [r for r in rows if r["task"] in ("segment", "both")]
    if clf:
        lines += [
            "## Hand / non-hand",
            "",
            "| checkpoint | hand recall on the real prints, % [95 % interval] | non-hand "
            "specificity on simulated test non-hands, % [95 % interval] |",
            "|---|---|---|",
        ]
        for r in clf:
            lo, hi = r["hand_recall_ci"]
            slo, shi = r["specificity_ci"]
            lines.append(
                f"| `{r['checkpoint']}` | {_pct(r['hand_recall'])} [{_pct(lo)}, {_pct(hi)}] of "
                f"{r['n_real']} | {_pct(r['specificity'])} [{_pct(slo)}, {_pct(shi)}] of "
                f"{r['n_non_hand']} (`{r['negatives']}`) |"
            )
        lines.append("")
    if seg:
        head = " | ".join(PARTS)
        lines += [
            "## Parts in the real boxes (box-derived: each contact pixel in its smallest box)",
            "",
            f"| checkpoint | localised, % [95 % interval] | box IoU | IoU > 0.5, % | {head} |",
            "|---|---|---|---|" + "---|" * len(PARTS),
        ]
        for r in seg:
            lo, hi = r["localised_ci"]
            parts = " | ".join(
                f"{_pct(r['per_part'][p]['localised'])} ({r['per_part'][p]['boxes']})"
                for p in PARTS
            )
            lines.append(
                f"| `{r['checkpoint']}` | {_pct(r['localised'])} [{_pct(lo)}, {_pct(hi)}] of "
                f"{r['boxes']} | {r['box_iou']:.3f} | {_pct(r['box_iou_above_half'])} | {parts} |"
            )
        left_out = ", ".join(str(r["boxes_without_contact"]) for r in seg)
        lines += [
            "",
            "Per part: % localised (boxes). Chance is about 1 in 6. Boxes with no contact pixel "
            f"of their own are left out ({left_out}).",
            "",
        ]
        lines += confusion_markdown(seg) + direction_markdown(seg)
    return lines


def confusion_markdown(seg: list[dict]) -> list[str]:
    """Per segmenter: what each part's boxes were taken for, % of its boxes per class."""
    lines = ["### What each part's boxes are taken for", ""]
    for r in seg:
        lines += [
            f"`{r['checkpoint']}`: % of each real part's boxes by the class most of their "
            "pixels got.",
            "",
            "| real box | " + " | ".join(CLASS_NAMES) + " |",
            "|---|" + "---|" * len(CLASS_NAMES),
        ]
        for part, counts in r["taken_for"].items():
            n = max(1, sum(counts))
            lines.append(f"| {part} | " + " | ".join(f"{100 * c / n:.0f}" for c in counts) + " |")
        lines.append("")
    return lines


def direction_markdown(seg: list[dict]) -> list[str]:
    """Localisation by where the real print's fingers point (`by_direction`), a column per
    segmenter."""
    lines = [
        "### By where the fingers point",
        "",
        "Palm to fingers, degrees from +rows towards +columns, a left-drawn hand mirrored "
        "(`handskin stats`); % localised (boxes).",
        "",
        "| fingers point, deg | " + " | ".join(f"`{r['checkpoint']}`" for r in seg) + " |",
        "|---|" + "---|" * len(seg),
    ]
    for k, b in enumerate(seg[0]["by_direction"]):
        name = "no palm, thumb or finger"
        if b["from_deg"] is not None:
            name = f"{b['from_deg']} to {b['to_deg']}"
        cells = [r["by_direction"][k] for r in seg]
        lines.append(
            f"| {name} | "
            + " | ".join(f"{_pct(c['localised'])} ({c['boxes']})" for c in cells)
            + " |"
        )
    return [*lines, ""]


def real_picture(folder: str | Path, predictions: list[np.ndarray], png: Path, n: int = 8) -> Path:
    """Prints 0, k, 2k, ... (``n`` of them) with the predicted parts in their colours over the
    grey image and each real box outlined in its part's colour."""
    prints = BoxFolder.open(folder)
    picks = np.linspace(0, len(prints) - 1, min(n, len(prints))).round().astype(int)
    cols = 4
    fig = Figure(figsize=(16, 3.2 * int(np.ceil(len(picks) / cols))), layout="constrained")
    axes = np.atleast_1d(fig.subplots(int(np.ceil(len(picks) / cols)), cols)).ravel()
    for ax, i in zip(axes, picks, strict=False):
        p, pred = prints[int(i)], predictions[int(i)]
        rgb = np.repeat(p.image[..., None], 3, axis=2).astype(float) / 255
        mask = pred > 0
        rgb[mask] = 0.35 * rgb[mask] + 0.65 * PALETTE[pred[mask]] / 255
        ax.imshow(rgb, interpolation="nearest")
        right = 0
        for b in localise(pred, p.image, p.boxes):
            right += b["majority"] == b["part"]
        for part, r0, r1, c0, c1 in p.boxes.tolist():
            colour = PALETTE[part] / 255
            ax.add_patch(
                Rectangle((c0 - 0.5, r0 - 0.5), c1 - c0, r1 - r0, fill=False, ec=colour, lw=1.6)
            )
        ax.set_title(f"{p.name}: {right} of {len(p.boxes)} boxes localised", fontsize=9)
        ax.set_axis_off()
    for ax in axes[len(picks) :]:
        ax.set_axis_off()
    handles = [Rectangle((0, 0), 1, 1, color=PALETTE[c] / 255) for c in range(1, len(CLASS_NAMES))]
    fig.legend(handles, PARTS, loc="outside lower center", ncols=len(PARTS), fontsize=9)
    fig.suptitle("real prints: real boxes outlined, predicted parts filled", fontsize=11)
    return save_figure(fig, png, dpi=90)


def write_real_report(rows: list[dict], path: str | Path, header: str) -> Path:
    """The markdown report at ``path`` and its rows as ``.json`` beside it."""
    path = Path(path)
    lines = ["# handskin evaluation on real prints", "", header, "", *real_markdown(rows)]
    write_text_atomic(path, "\n".join(lines) + "\n")
    write_text_atomic(path.with_suffix(".json"), json.dumps(rows, indent=1))
    return path
