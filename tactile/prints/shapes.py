"""The shape of a hand print, measured alike on real box-labelled prints and on simulated ones:
six statistics that say whether a print is broken into marks per finger and pad, how large it
is, and which parts it shows.

    s = print_shape(image, boxes)              # one print: image (H, W) uint8, boxes (K, 5)
    real = folder_shapes(BoxFolder.open(...))  # every print of a folder
    sim = dataset_shapes(open_dataset("data/paper"))   # its hand prints, with their actions
    shapes_markdown({"fold1": real, "default set": sim})

Contact: grey level above ``level`` (4: levels 1 to 4 are resampling residue of the real
images) in 8-connected blobs of at least ``min_blob_px`` pixels (30), on a grid of ``step_mm``
mm of skin a pixel (the paper's images: `tactile.dataset.boxes.PAPER_PIXEL_MM`). The statistics
of a print:

- ``blobs``: its separate blobs;
- ``area_mm2``: its contact pixels times the pixel area;
- ``span_mm``: the longer side of the box around them;
- ``parts``: the hand parts boxed (a real print) or showing at least ``min_blob_px`` contact
  pixels (a simulated one);
- ``finger_blobs``: the share of its boxed fingers that leave a blob of their own: a blob whose
  box-derived labels (`tactile.dataset.boxes.box_labels`) are all that finger's;
- ``palm_share``: the palm's share of its box-labelled contact pixels.

A simulated print is boxed as a person would box it: one tight box per part around that part's
contact pixels (`boxes_of_labels`), so both sides go through the same box rule.

Where the parts lie (`part_layout`, `LAYOUT`): distances in mm between the centres of a print's
part boxes (a part boxed twice: its largest box), averaged over the pairs the print shows: palm
to each finger, palm to thumb, neighbouring fingers, index to little finger. They say whether a
simulated hand puts its marks as far apart as real hands do (marks closer than a pad pitch fuse).

How far a print reaches each way (`EXTENT`): the rows and the columns its contact spans, in mm
(on the paper's map rows run around the link, columns along it): the span alone does not say
whether a hand wraps the link or lies along it.

Which way a print is drawn (`CHIRALITY`): ``thumb_right`` is 1 when the thumb's box lies to the
right of the line from the palm's box to the fingers' (their mean centre), with the fingers
pointing up and rows running down, 0 when to the left (NaN without palm, thumb and a finger): a
right hand seen through the skin, as the paper's images show it, reads 1; the same hand seen from
outside reads 0. Its mean over a set is the share of prints drawn like a right hand.
``little_along`` is 1 when the little finger's box centre lies within 45 deg of +columns from the
index finger's: where people stood (real folds 0.71 / 0.69: the index nearer the link's base).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import pairwise

import numpy as np
from scipy import ndimage

from tactile.dataset.boxes import CONTACT_LEVEL, box_labels
from tactile.images.labels import CLASS_NAMES, IGNORE
from tactile.prints.measures import EIGHT_NEIGHBOURS, action_names

MIN_BLOB_PX = 30  # blobs below this many pixels are specks, not marks (real_hands README)
PALM = CLASS_NAMES.index("palm")
THUMB, INDEX, PINKIE = (CLASS_NAMES.index(n) for n in ("thumb", "index", "pinkie"))
FINGERS = tuple(range(INDEX, PINKIE + 1))  # index, middle, ring, little, in order across the hand
STATISTICS = {  # name: (what the report calls it, format)
    "blobs": ("separate blobs per print", "{:.0f}"),
    "area_mm2": ("contact area, mm²", "{:,.0f}"),
    "span_mm": ("span of the print (largest extent), mm", "{:.0f}"),
    "parts": ("hand parts boxed or labelled", "{:.0f}"),
    "finger_blobs": ("share of a print's fingers that leave a blob of their own", "{:.2f}"),
    "palm_share": ("palm's share of the boxed contact pixels", "{:.2f}"),
}

LAYOUT = {  # name: what the report calls it (mm between part box centres)
    "palm_finger_mm": "palm to a finger",
    "palm_thumb_mm": "palm to thumb",
    "neighbour_mm": "neighbouring fingers",
    "index_pinkie_mm": "index to little finger",
}
EXTENT = {  # name: what the report calls it (mm of skin the contact spans)
    "rows_mm": "down the rows (around the link on the paper's map)",
    "cols_mm": "along the columns (along the link)",
}
DIRECTION = {  # name: what the report calls it (degrees on the map)
    "fingers_deg": "palm to fingers, deg from +rows towards +columns (a left hand mirrored)",
}
CHIRALITY = {
    "thumb_right": "prints drawn like a right hand (thumb right of the fingers)",
    "little_along": "prints with index to little finger along +columns (+-45 deg)",
}
WITHOUT_PALM = "prints without a palm (the digits alone)"


@dataclass
class Shapes:
    """The statistics of S prints: one (S,) float array per name of `STATISTICS`, `EXTENT`,
    `LAYOUT`, `DIRECTION` (NaN where a print has no value: no finger boxed, no boxed contact, a
    part missing), and each print's ``action``."""

    values: dict[str, np.ndarray]
    action: np.ndarray = field(default_factory=lambda: np.zeros(0, str))

    def __len__(self) -> int:
        return len(self.values["blobs"])

    def subset(self, mask: np.ndarray) -> Shapes:
        return Shapes({k: v[mask] for k, v in self.values.items()}, self.action[mask])


def contact_blobs(image: np.ndarray, level: int, min_blob_px: int) -> np.ndarray:
    """(H, W) int64: each contact pixel's blob (1..B, blobs of at least ``min_blob_px``), 0
    elsewhere."""
    lab, _ = ndimage.label(image > level, structure=EIGHT_NEIGHBOURS)
    sizes = np.bincount(lab.ravel())
    keep = sizes >= min_blob_px
    keep[0] = False
    renumber = np.cumsum(keep) * keep
    return renumber[lab]


def print_shape(
    image: np.ndarray,
    boxes: np.ndarray,
    step_mm: float = 1.0,
    level: int = CONTACT_LEVEL,
    min_blob_px: int = MIN_BLOB_PX,
) -> dict[str, float]:
    """The six statistics and the extents of one print: ``image`` (H, W) uint8, ``boxes`` (K, 5)
    int (part, r0, r1, c0, c1, px)."""
    blobs = contact_blobs(image, level, min_blob_px)
    contact = blobs > 0
    rows, cols = np.nonzero(contact)
    down, along = (np.ptp(rows) + 1, np.ptp(cols) + 1) if len(rows) else (0, 0)
    labels = np.where(contact, box_labels(image, boxes, level), 0)
    boxed = (labels > 0) & (labels != IGNORE)
    fingers = set(boxes[:, 0].tolist()) - {PALM}
    own = set()
    for b in range(1, int(blobs.max(initial=0)) + 1):
        parts = np.unique(labels[(blobs == b) & boxed])
        if len(parts) == 1 and parts[0] in fingers:
            own.add(int(parts[0]))
    return {
        "blobs": float(blobs.max(initial=0)),
        "area_mm2": float(contact.sum()) * step_mm**2,
        "span_mm": float(max(down, along)) * step_mm,
        "rows_mm": float(down) * step_mm,
        "cols_mm": float(along) * step_mm,
        "parts": float(len(set(boxes[:, 0].tolist()))),
        "finger_blobs": len(own) / len(fingers) if fingers else np.nan,
        "palm_share": (labels == PALM).sum() / boxed.sum() if boxed.any() else np.nan,
    }


def part_layout(boxes: np.ndarray, step_mm: float = 1.0) -> dict[str, float]:
    """Distances (mm) between the part box centres of one print, ``boxes`` (K, 5+) int (part, r0,
    r1, c0, c1, ...) on a ``step_mm`` grid, one value per name of `LAYOUT` (NaN where the print
    lacks the parts): each the mean over the print's pairs of that kind; ``thumb_right``,
    ``little_along`` (`CHIRALITY`); and ``fingers_deg`` (`DIRECTION`): where the fingers point,
    the direction from the palm's centre to the mean of the fingers' in degrees from +rows
    towards +columns, a left-drawn hand's mirrored across the rows (-180 - angle) so that both
    hands read alike (NaN without palm, thumb and a finger)."""
    centre = {}
    for part in np.unique(boxes[:, 0]).tolist():
        b = boxes[boxes[:, 0] == part]
        big = b[np.argmax((b[:, 2] - b[:, 1]) * (b[:, 4] - b[:, 3]))]
        centre[part] = step_mm * np.array([big[1] + big[2], big[3] + big[4]], float) / 2.0

    def mean_dist(pairs) -> float:
        d = [np.linalg.norm(centre[a] - centre[b]) for a, b in pairs if a in centre and b in centre]
        return float(np.mean(d)) if d else np.nan

    fingers = [centre[f] for f in FINGERS if f in centre]
    little_along = np.nan
    if INDEX in centre and PINKIE in centre:
        dr, dc = centre[PINKIE] - centre[INDEX]
        little_along = float(dc > abs(dr))
    thumb_right = fingers_deg = np.nan
    if PALM in centre and THUMB in centre and fingers:
        (vr, vc), (wr, wc) = np.mean(fingers, axis=0) - centre[PALM], centre[THUMB] - centre[PALM]
        thumb_right = float(vc * wr - vr * wc > 0)
        angle = np.degrees(np.arctan2(vc, vr))
        angle = angle if thumb_right else -180.0 - angle
        fingers_deg = float((angle + 180.0) % 360.0 - 180.0)
    return {
        "thumb_right": thumb_right,
        "fingers_deg": fingers_deg,
        "little_along": little_along,
        "palm_finger_mm": mean_dist((PALM, f) for f in FINGERS),
        "palm_thumb_mm": mean_dist([(PALM, THUMB)]),
        "neighbour_mm": mean_dist(pairwise(FINGERS)),
        "index_pinkie_mm": mean_dist([(INDEX, PINKIE)]),
    }


def boxes_of_labels(
    label_image: np.ndarray,
    image: np.ndarray,
    level: int = CONTACT_LEVEL,
    min_blob_px: int = MIN_BLOB_PX,
) -> np.ndarray:
    """(K, 5) int64: one tight box per hand part of a simulated print (its label image (H, W)),
    around the part's contact pixels, for each part with at least ``min_blob_px`` of them."""
    contact = contact_blobs(image, level, min_blob_px) > 0
    out = []
    for part in range(1, len(CLASS_NAMES)):
        rows, cols = np.nonzero(contact & (label_image == part))
        if len(rows) >= min_blob_px:
            out.append((part, rows.min(), rows.max() + 1, cols.min(), cols.max() + 1))
    return np.array(out, np.int64).reshape(-1, 5)


def _stack(rows: list[dict[str, float]], action) -> Shapes:
    keys = (*STATISTICS, *EXTENT, *LAYOUT, *DIRECTION, *CHIRALITY)
    values = {k: np.array([r[k] for r in rows], float) for k in keys}
    return Shapes(values, np.asarray(action, str))


def folder_shapes(
    folder, level: int = CONTACT_LEVEL, min_blob_px: int = MIN_BLOB_PX, step_mm: float = 1.0
) -> Shapes:
    """The statistics of every print of a `tactile.dataset.boxes.BoxFolder`, ``step_mm`` mm of
    skin a pixel of its native frame (1.0: in pixels; the paper's images: `PAPER_PIXEL_MM`)."""
    rows = [
        print_shape(p.image, p.boxes, step_mm, level, min_blob_px) | part_layout(p.boxes, step_mm)
        for p in folder
    ]
    return _stack(rows, np.full(len(rows), "", dtype=object))


def dataset_shapes(ds, level: int = CONTACT_LEVEL, min_blob_px: int = MIN_BLOB_PX) -> Shapes:
    """The statistics of the hand prints of a dataset (a `tactile.dataset.DatasetReader` with
    ``image`` and ``label_image``), each boxed by `boxes_of_labels`, with its action."""
    hands = np.flatnonzero(ds.is_hand[:] == 1)
    step = float(ds.map.step_mm)
    rows = []
    for i in hands.tolist():
        image, labels = np.asarray(ds.image[i]), np.asarray(ds.label_image[i])
        boxes = boxes_of_labels(labels, image, level, min_blob_px)
        rows.append(print_shape(image, boxes, step, level, min_blob_px) | part_layout(boxes, step))
    return _stack(rows, action_names(ds, ds.action[:] if "action" in ds.fields else None)[hands])


def chirality(shapes: Shapes, key: str = "thumb_right") -> float:
    """The share of a set's prints drawn like a right hand, or with ``key`` "little_along" the
    index to little finger along +columns (`CHIRALITY`; NaN without any)."""
    x = shapes.values[key]
    x = x[np.isfinite(x)]
    return float(x.mean()) if len(x) else np.nan


def without_palm(shapes: Shapes) -> float:
    """The share of a set's prints with no palm pixel (``palm_share`` 0: the digits alone
    touched; NaN without any print). Real folds: 31 %."""
    x = shapes.values["palm_share"]
    x = x[np.isfinite(x)]
    return float((x == 0).mean()) if len(x) else np.nan


def quartiles(x: np.ndarray) -> tuple[float, float, float] | None:
    """(25th percentile, median, 75th percentile) of the finite values, None without any."""
    x = x[np.isfinite(x)]
    return None if not len(x) else tuple(float(v) for v in np.percentile(x, [25, 50, 75]))


def inside(value: float, iqr: tuple[float, float, float] | None) -> bool:
    """Whether ``value`` lies inside the interquartile range of ``iqr`` (ends included)."""
    return iqr is not None and iqr[0] <= value <= iqr[2]


def shapes_markdown(sets: dict[str, Shapes], reference: str | None = None) -> str:
    """The six statistics of each named set as median [IQR], side by side, then its extents
    (`EXTENT`), where the parts lie (`LAYOUT`) and where the fingers point (`DIRECTION`) alike;
    with ``reference`` (a set's name), a last column says whether each other set's median lies
    inside its IQR. Sets with actions get a table of medians by action."""
    layout = {k: (f"{label}, mm", "{:.0f}") for k, label in LAYOUT.items()}
    lines = _table(sets, reference, "print statistic", STATISTICS)
    lines += ["", "How far the contact reaches each way.", ""]
    extent = {k: (f"{label}, mm", "{:.0f}") for k, label in EXTENT.items()}
    lines += _table(sets, reference, "print extent", extent)
    lines += ["", "Where the parts lie: distances between part box centres.", ""]
    lines += _table(sets, reference, "part box centres", layout)
    lines += ["", "Where the fingers point.", ""]
    direction = {k: (label, "{:.0f}") for k, label in DIRECTION.items()}
    lines += _table(sets, reference, "direction", direction)
    for key, label in CHIRALITY.items():
        shares = [f"{n} {chirality(sets[n], key):.2f}" for n in sets]
        if any(np.isfinite(chirality(sets[n], key)) for n in sets):
            lines += ["", f"Share of {label}: {', '.join(shares)}."]
    palmless = [f"{n} {without_palm(sets[n]):.2f}" for n in sets if len(sets[n].values["blobs"])]
    lines += ["", f"Share of {WITHOUT_PALM}: {', '.join(palmless)}."]
    for n in sets:
        lines += _by_action(n, sets[n])
    return "\n".join(lines) + "\n"


def _table(sets: dict[str, Shapes], reference: str | None, first: str, items: dict) -> list[str]:
    names = list(sets)
    head = [first, *(f"{n} ({len(sets[n])} prints): median [IQR]" for n in names)]
    if reference is not None:
        head.append(f"inside {reference}'s IQR")
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for key, (label, fmt) in items.items():
        cells = [label]
        for n in names:
            q = quartiles(sets[n].values[key])
            cells.append(
                "n/a"
                if q is None
                else f"{fmt.format(q[1])} [{fmt.format(q[0])}, {fmt.format(q[2])}]"
            )
        if reference is not None:
            ref = quartiles(sets[reference].values[key])
            others = [
                n for n in names if n != reference and quartiles(sets[n].values[key]) is not None
            ]
            cells.append(
                ", ".join(
                    f"{n}: {'yes' if inside(quartiles(sets[n].values[key])[1], ref) else 'no'}"
                    for n in others
                )
            )
        lines.append("| " + " | ".join(cells) + " |")
    return lines


def _by_action(name: str, shapes: Shapes) -> list[str]:
    actions = sorted({a for a in shapes.action.tolist() if a})
    if not actions:
        return []
    head = ["action", "prints", *(STATISTICS[k][0] for k in STATISTICS)]
    out = ["", f"{name}, medians by action:", "", "| " + " | ".join(head) + " |"]
    out.append("|" + "---|" * len(head))
    for a in actions:
        sub = shapes.subset(shapes.action == a)
        cells = [a, str(len(sub))]
        for key, (_, fmt) in STATISTICS.items():
            q = quartiles(sub.values[key])
            cells.append("n/a" if q is None else fmt.format(q[1]))
        out.append("| " + " | ".join(cells) + " |")
    return out
