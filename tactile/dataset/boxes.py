"""Real tactile prints with a box per hand part: a folder of images and YOLO label files, as the
paper's pipeline makes the images and people box the parts they see.

    names = ["palm", "thumb", "index", "middle", "ring", "pinkie"]    # the label files' order
    real = BoxFolder.open("../shared/data/real_hands/fold1", names, frame_px=(247, 362))
    p = real[0]        # p.image (247, 362) uint8 at 1 mm; p.boxes (K, 5): part, r0, r1, c0, c1
    labels = box_labels(p.image, p.boxes)   # (H, W) uint8: the box-derived label image

Layout: ``ROOT/images/<name>.{png,jpg,jpeg,bmp}`` and ``ROOT/labels/<name>.txt``, one box per
line, ``class cx cy w h`` normalised to [0, 1] by the image (YOLO). The class names, in the
files' order, come from ``classes`` or from a ``data.yaml`` (``names:``) in ROOT or its parent;
they name the parts of `tactile.images.labels.CLASS_NAMES` (``little`` and ``pinky`` mean
pinkie). A labelling tool may have stretched the images (to squares): ``frame_px`` (rows,
columns) is the native frame each image is resized back to (bilinear), boxes included.

`ingest_boxes` writes a folder of this layout that describes itself: images in their native
frame and a ``data.yaml`` with the part names, the frame and ``labels_from: boxes``; training,
evaluation and statistics then need no flags (``handskin ingest-boxes``).

Box-derived labels (`box_labels`) follow one stated rule: a contact pixel (grey level above
``level``) inside a box takes that box's part, inside several boxes the smallest box's; a
contact pixel in no box and a pixel at a grey level of 1 to ``level`` (resampling residue) are
`IGNORE` (no loss or score counts them); a pixel of level 0 is background. Such labels say what
the boxes say, not what touched each pixel: wherever stored or reported they are marked
box-derived (`LABELS_FROM`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from PIL import Image, UnidentifiedImageError

from tactile.errors import DataError
from tactile.files import save_image, write_text_atomic
from tactile.images.labels import CLASS_NAMES, IGNORE

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp")
CONTACT_LEVEL = 4  # grey levels 1..4 are resampling residue, not contact (real_hands README)
EDGE_PX = 1e-3  # px: YOLO files round to 6 decimals, 4e-4 px of a 362 px frame
LABELS_FROM = "boxes"  # what a box-derived label image says it was made from
ALIASES = {"little": "pinkie", "pinky": "pinkie", "little_finger": "pinkie"}
# Skin under a pixel of the paper's tactile images, mm. Their grid is 1 mm of their flat map, but
# the hands that made the real prints put their part boxes 1.33-1.40 times (mean 1.36) as far
# apart as hands of the paper's sizes (15-22 cm) do on a map at 1 mm of skin: palm to finger,
# palm to thumb, neighbouring fingers, index to little finger (docs/stats.md). `handskin stats`
# reads box folders at this step; the generator draws its images on this grid.
PAPER_PIXEL_MM = 0.735


@dataclass(frozen=True)
class BoxPrint:
    """One print: ``image`` (H, W) uint8 grey levels in the native frame, ``boxes`` (K, 5) int64
    rows ``part, r0, r1, c0, c1`` (part id of `CLASS_NAMES`; rows r0:r1, columns c0:c1, px),
    ``name`` its file's stem."""

    name: str
    image: np.ndarray
    boxes: np.ndarray


def is_box_folder(path: str | Path) -> bool:
    """True for a folder holding ``images/`` and ``labels/`` with at least one ``.txt`` file."""
    path = Path(path)
    labels = path / "labels"
    return (path / "images").is_dir() and labels.is_dir() and any(labels.glob("*.txt"))


def part_ids(names: list[str] | tuple[str, ...], where: str) -> np.ndarray:
    """(C,) int64: the `CLASS_NAMES` id of each of a folder's class names; DataError naming the
    unknown ones and the known parts."""
    ids = []
    for name in names:
        key = ALIASES.get(str(name).strip().lower(), str(name).strip().lower())
        if key not in CLASS_NAMES[1:]:
            raise DataError(
                f"{where}: class {name!r} is no hand part; known: {', '.join(CLASS_NAMES[1:])} "
                "(little or pinky for pinkie). Fix: give the folder's class names in its order"
            )
        ids.append(CLASS_NAMES.index(key))
    if len(set(ids)) != len(ids):
        raise DataError(f"{where}: a hand part is named twice in {list(names)}")
    return np.array(ids, np.int64)


def read_data_yaml(root: Path) -> tuple[list[str], tuple[int, int] | None]:
    """(class names, native frame or None) of ``data.yaml`` in ``root`` or its parent: its
    ``names`` (a list, or a mapping id -> name) and its ``frame`` ([rows, columns], written by
    `ingest_boxes`); DataError when there is none."""
    for path in (root / "data.yaml", root.parent / "data.yaml"):
        if path.is_file():
            try:
                meta = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
                names, frame = meta.get("names"), meta.get("frame")
            except (yaml.YAMLError, UnicodeDecodeError, AttributeError) as err:
                raise DataError(f"{path}: not a YAML mapping with names ({err})") from None
            if isinstance(names, dict):
                names = [names[k] for k in sorted(names)]
            if not isinstance(names, list) or not names:
                raise DataError(f"{path}: no list of class names under 'names'")
            ok = (
                isinstance(frame, list)
                and len(frame) == 2
                and all(isinstance(v, int) for v in frame)
            )
            if frame is not None and not ok:
                raise DataError(f"{path}: frame {frame!r} is not [rows, columns] in px")
            return [str(n) for n in names], None if frame is None else (frame[0], frame[1])
    raise DataError(
        f"{root}: no data.yaml names the box classes. Fix: give them in the files' order, e.g. "
        "--classes palm,thumb,index,middle,ring,pinkie (and the native frame, --frame 247x362), "
        "or write a self-describing copy once: handskin ingest-boxes"
    )


def parse_boxes(path: Path, ids: np.ndarray, frame_px: tuple[int, int]) -> np.ndarray:
    """(K, 5) int64 boxes of one YOLO label file in a ``frame_px`` (rows, columns) frame: each
    normalised edge scaled and rounded outwards to whole pixels, clipped to the frame."""
    rows, cols = frame_px
    out = []
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if not line.strip():
            continue
        try:
            c, cx, cy, w, h = line.split()
            c, cx, cy, w, h = int(c), float(cx), float(cy), float(w), float(h)
        except ValueError:
            raise DataError(
                f"{path}, line {n}: {line.strip()!r} is not 'class cx cy w h'"
            ) from None
        if not 0 <= c < len(ids):
            raise DataError(f"{path}, line {n}: class {c} of {len(ids)} named classes")
        if not (0 <= cx <= 1 and 0 <= cy <= 1 and 0 < w <= 1 and 0 < h <= 1):
            raise DataError(f"{path}, line {n}: a box outside [0, 1]: {line.strip()!r}")
        # outwards to whole pixels, an edge within EDGE_PX of a pixel border staying on it
        r0, r1 = np.floor((cy - h / 2) * rows + EDGE_PX), np.ceil((cy + h / 2) * rows - EDGE_PX)
        c0, c1 = np.floor((cx - w / 2) * cols + EDGE_PX), np.ceil((cx + w / 2) * cols - EDGE_PX)
        r0, c0 = max(int(r0), 0), max(int(c0), 0)
        out.append((ids[c], r0, min(int(r1), rows), c0, min(int(c1), cols)))
    return np.array(out, np.int64).reshape(-1, 5)


def parse_frame(frame: str | None) -> tuple[int, int] | None:
    """``--frame ROWSxCOLUMNS`` as (rows, columns) px; DataError in the flag's words."""
    if frame is None:
        return None
    try:
        rows, cols = (int(v) for v in frame.lower().split("x"))
    except ValueError:
        raise DataError(f"--frame {frame!r}: give ROWSxCOLUMNS in px, e.g. 247x362") from None
    if rows < 1 or cols < 1:
        raise DataError(f"--frame {frame}: both sides must be >= 1 px")
    return rows, cols


class BoxFolder:
    """A folder of box-labelled prints (see the module); ``len``, ``[i]`` -> `BoxPrint`."""

    def __init__(self, root: Path, files: list[Path], ids: np.ndarray, frame_px) -> None:
        self.root, self.files, self.part_ids = root, files, ids
        self.frame_px = None if frame_px is None else (int(frame_px[0]), int(frame_px[1]))

    @classmethod
    def open(
        cls,
        root: str | Path,
        classes: list[str] | tuple[str, ...] | None = None,
        frame_px: tuple[int, int] | None = None,
    ) -> BoxFolder:
        """The folder at ``root``, checked before any image is read: its layout, the class
        names (``classes`` or ``data.yaml``), a label file per image."""
        root = Path(root)
        if not is_box_folder(root):
            raise DataError(
                f"{root}: not a folder of box-labelled prints. Fix: give a folder holding "
                "images/ and labels/ (YOLO .txt files, one per image)"
            )
        if not classes or frame_px is None:
            try:
                names, frame = read_data_yaml(root)
            except DataError:
                if not classes:
                    raise
                names, frame = list(classes), None
            classes, frame_px = classes or names, frame_px if frame_px is not None else frame
        ids = part_ids(list(classes), str(root))
        files = sorted(
            (p for p in (root / "images").iterdir() if p.suffix.lower() in IMAGE_SUFFIXES),
            key=lambda p: (len(p.stem), p.stem),
        )
        missing = [p.name for p in files if not (root / "labels" / f"{p.stem}.txt").is_file()]
        if not files or missing:
            raise DataError(
                f"{root}: {'no images' if not files else f'no label file for {missing[:3]}'}. "
                "Fix: one labels/<name>.txt per images/<name> (empty for no box)"
            )
        if frame_px is not None and min(frame_px) < 1:
            raise DataError(f"--frame {frame_px}: give rows x columns, both >= 1 px")
        return cls(root, files, ids, frame_px)

    def __len__(self) -> int:
        return len(self.files)

    @property
    def names(self) -> list[str]:
        return [p.stem for p in self.files]

    def __getitem__(self, i: int) -> BoxPrint:
        path = self.files[i]
        try:
            with Image.open(path) as im:
                grey = im.convert("L")
                if self.frame_px is not None and grey.size != self.frame_px[::-1]:
                    grey = grey.resize(self.frame_px[::-1], Image.Resampling.BILINEAR)
                image = np.asarray(grey, np.uint8)
        except (OSError, UnidentifiedImageError) as err:
            raise DataError(f"{path} is not a readable image ({err})") from None
        boxes = parse_boxes(self.root / "labels" / f"{path.stem}.txt", self.part_ids, image.shape)
        return BoxPrint(path.stem, image, boxes)


def box_labels(image: np.ndarray, boxes: np.ndarray, level: int = CONTACT_LEVEL) -> np.ndarray:
    """(H, W) uint8 box-derived labels of ``image`` (H, W) uint8 and its ``boxes`` (K, 5): the
    module's rule (smallest box wins; `IGNORE` for residue and for contact in no box)."""
    return np.asarray(_assign(image, boxes, level)[0])


def box_members(image: np.ndarray, boxes: np.ndarray, level: int = CONTACT_LEVEL) -> np.ndarray:
    """(H, W) int64: the index of the box each contact pixel belongs to by the rule of
    `box_labels` (-1 for none)."""
    return _assign(image, boxes, level)[1]


def _assign(image: np.ndarray, boxes: np.ndarray, level: int) -> tuple[np.ndarray, np.ndarray]:
    contact = image > level
    labels = np.where(image > 0, IGNORE, 0).astype(np.uint8)
    member = np.full(image.shape, -1, np.int64)
    area = (boxes[:, 2] - boxes[:, 1]) * (boxes[:, 4] - boxes[:, 3])
    for k in np.argsort(-area, kind="stable"):  # larger first: a smaller box writes over it
        part, r0, r1, c0, c1 = boxes[k]
        inside = contact[r0:r1, c0:c1]
        labels[r0:r1, c0:c1][inside] = part
        member[r0:r1, c0:c1][inside] = k
    return labels, member


def ingest_boxes(
    src: str | Path,
    out: str | Path,
    classes: list[str] | tuple[str, ...] | None = None,
    frame_px: tuple[int, int] | None = None,
) -> Path:
    """Write the prints of the box folder ``src`` to the new (or empty) folder ``out``: each
    image in its native frame (PNG), its label file as it is (normalised boxes hold in any
    frame), and a ``data.yaml`` naming the parts, the frame and ``labels_from: boxes``. Every
    image is read (and checked) before the first file is written. Returns ``out``."""
    folder = BoxFolder.open(src, classes, frame_px)
    out = Path(out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        raise DataError(f"--out {out}: not a new or empty folder. Fix: give a new folder")
    prints = [folder[i] for i in range(len(folder))]
    (out / "images").mkdir(parents=True)
    (out / "labels").mkdir()
    for path, p in zip(folder.files, prints, strict=True):
        save_image(Image.fromarray(p.image), out / "images" / f"{p.name}.png")
        label = folder.root / "labels" / f"{path.stem}.txt"
        write_text_atomic(out / "labels" / f"{p.name}.txt", label.read_text(encoding="utf-8"))
    rows, cols = prints[0].image.shape
    meta = {
        "names": [CLASS_NAMES[i] for i in folder.part_ids.tolist()],
        "frame": [int(rows), int(cols)],
        "labels_from": LABELS_FROM,
        "source": str(Path(src).resolve()),
    }
    write_text_atomic(out / "data.yaml", yaml.safe_dump(meta, sort_keys=False))
    return out
