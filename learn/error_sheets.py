"""Pictures of where a model fails, drawn beside an evaluation report: a classifier's most
confident errors, a segmenter's lowest-mIoU test images (truth beside prediction), and the
report's lines that link them.

    rows = [evaluate_checkpoint("runs/handsnet/best.pt", "out/forearm")]
    save_error_sheets(rows, "out/forearm", "report.md")  # report_errors_HandsNet.png
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from learn.row_labels import row_labels

#: Tiles on a classifier's sheet of its most confident errors.
N_ERROR_TILES = 18


def save_error_sheets(rows: list[dict], data: str | Path, report: str | Path) -> list[Path]:
    """For each row of a handskin dataset, a PNG beside the report of where the model fails:
    a classifier's `N_ERROR_TILES` most confident errors (the stored 1 mm map images,
    captioned with the truth, the probability given to the wrong class (an SVM's margin), the
    contactor and the active taxels), a segmenter's worst test images by their own mIoU (its
    input at the network's size with the true labels, then with its predicted labels). The row's
    ``error_sheet`` is set to the file name. Returns the files written."""
    report, out = Path(report), []
    for r, label in zip(rows, row_labels(rows), strict=True):
        slug = re.sub(r"[^A-Za-z0-9]+", "_", label).strip("_")
        path = report.with_name(f"{report.stem}_errors_{slug}.png")
        if r.get("errors"):
            _classifier_sheet(r, label, data, path)
        elif (r.get("worst") or {}).get("images"):
            _segmenter_sheet(r, label, data, path)
        else:
            continue
        r["error_sheet"] = path.name
        out.append(path)
    return out


def _classifier_sheet(r: dict, label: str, data: str | Path, path: Path) -> None:
    from tactile.dataset.reader import DatasetReader
    from tactile.sheet import save_contact_sheet

    errors = r["errors"][:N_ERROR_TILES]
    with DatasetReader(data) as reader:
        images = np.stack([reader.image[e["index"]] for e in errors])
    titles = [
        f"#{e['index']} {e['true']} as {e['predicted']} {_confidence(e)}\n"
        f"{str(e.get('contactor', '')).split(': ')[-1]}, "
        f"{e.get('active taxels', '?')} taxels"
        + (f", {e['hand parts']}" if e.get("hand parts") else "")
        for e in errors
    ]
    save_contact_sheet(
        path,
        images,
        titles=titles,
        n_cols=6,
        title=f"{label}: its {len(errors)} most confident errors of "
        f"{len(r['errors'])} (test split)",
    )


def _confidence(error: dict) -> str:
    """``p 0.93`` (a network's softmax probability) or ``margin 1.20`` (an SVM's)."""
    if "probability" in error:
        return f"p {error['probability']:.2f}"
    return f"margin {error['margin']:.2f}"


def _segmenter_sheet(r: dict, label: str, data: str | Path, path: Path) -> None:
    """Pairs of tiles: truth, then prediction, of the images whose maps the row carries."""
    from learn.inputs import input_canvas, net_input, net_labels
    from learn.worst import unpack_labels
    from tactile.dataset.reader import DatasetReader
    from tactile.sheet import save_contact_sheet

    pred = unpack_labels(r["worst"]["maps"])
    worst = r["worst"]["images"][: len(pred)]
    size = tuple(r.get("input_size") or r["config"]["model"]["input_size"])
    with DatasetReader(data) as reader:
        image = np.stack([reader.image[w["index"]] for w in worst]) / 255.0
        canvas = input_canvas(r.get("canvas_mm"), reader.map.step_mm)
        truth = net_labels(np.stack([reader.label_image[w["index"]] for w in worst]), size, canvas)
    x = np.round(255 * net_input(image, size, "segment", canvas)).astype(np.uint8)
    titles = []
    for w in worst:
        titles += [
            f"#{w['index']} truth\n{w.get('action', '')}, "
            f"{w.get('hand parts touching', '?')} parts",
            f"predicted: mIoU {100 * w['mean_iou']:.0f} %\n"
            f"pixel accuracy {100 * w['pixel_accuracy']:.0f} %",
        ]
    save_contact_sheet(
        path,
        np.repeat(x, 2, axis=0),
        labels=np.stack([truth, pred], axis=1).reshape(-1, *size),
        titles=titles,
        n_cols=6,
        title=f"{label}: its {len(worst)} test images with the lowest mIoU (truth, prediction)",
    )


def error_text(r: dict) -> list[str]:
    """The link to a row's sheet of where it fails, with the count behind it."""
    if not r.get("error_sheet"):
        return []
    if r.get("errors"):
        shown = min(N_ERROR_TILES, len(r["errors"]))
        sure = (
            "SVM margin" if "margin" in r["errors"][0] else "probability given to the wrong class"
        )
        return [
            f"Its {shown} most confident errors of {len(r['errors'])} (sample index, truth, "
            f"{sure}, contactor, active taxels, hand parts pressing):",
            "",
            f"![most confident errors]({r['error_sheet']})",
            "",
        ]
    worst = r["worst"]["images"]
    shown = r["worst"]["maps"]["shape"][0]
    listed = ", ".join(f"#{w['index']} ({100 * w['mean_iou']:.0f} %)" for w in worst[:20])
    return [
        f"Its {shown} test images with the lowest mIoU of {r['n_test']}, each scored on its "
        "own (sample index, action, hand parts touching; truth left, prediction right):",
        "",
        f"![lowest-mIoU test images]({r['error_sheet']})",
        "",
        f"The {min(20, len(worst))} lowest (sample index, mIoU): {listed}.",
        "",
    ]
