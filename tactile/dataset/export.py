"""Export a dataset as PNG folders, like the paper's supplementary material.

    OUT/hand/000012_subject3_grasp.png       grey tactile image (H, W) of a hand sample
    OUT/non_hand/000013_instance5.png        grey tactile image of a non-hand sample
    OUT/labels/000012_subject3_grasp.png     RGB label image of a hand sample (tactile.PALETTE)
    OUT/unlabelled/000014.png                images of a dataset without ``is_hand``

File names start with the sample index (6 digits), so they sort in dataset order. OUT/export.json
records the dataset exported (its fingerprint): a folder holding anything else is refused before
any work, so two datasets' images never mix; a folder holding this dataset's export (complete, or
cut short by a kill or a full disk) is resumed, the files already there kept. Each PNG is written
under a temporary name and renamed when complete.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
from PIL import Image
from tqdm import tqdm

from tactile.dataset.reader import DatasetReader, open_dataset
from tactile.errors import DataError
from tactile.files import atomic_path, remove_stale, writing
from tactile.images.labels import colorize

FOLDERS = ("hand", "non_hand", "labels", "unlabelled")
MARKER = "export.json"  # OUT/export.json: which dataset this folder is an export of
EXPORT_FORMAT = "handskin.export/1"


def _slug(text: str) -> str:
    """A file-name-safe version of ``text`` (letters, digits, -, _)."""
    return re.sub(r"[^A-Za-z0-9_-]+", "-", text).strip("-") or "none"


def sample_stem(ds: DatasetReader, i: int, actions: list[str]) -> str:
    """File stem of sample ``i``: index, then subject and action (hand) or instance (non-hand)."""
    parts = [f"{i:06d}"]
    hand = "is_hand" in ds.fields and int(ds.is_hand[i]) == 1
    if hand and "subject_id" in ds.fields:
        parts.append(f"subject{int(ds.subject_id[i])}")
    if hand and "action" in ds.fields:
        a = int(ds.action[i])
        parts.append(_slug(actions[a]) if 0 <= a < len(actions) else f"action{a}")
    if not hand and "instance_id" in ds.fields and int(ds.instance_id[i]) >= 0:
        parts.append(f"instance{int(ds.instance_id[i])}")
    return "_".join(parts)


def save_png(path: Path, image: np.ndarray) -> None:
    """Write an (H, W) uint8 grey or (H, W, 3) uint8 RGB image as PNG, atomically."""
    with atomic_path(path) as tmp:
        Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8)).save(tmp, format="PNG")


def export_record(ds: DatasetReader) -> dict[str, object]:
    """What OUT/export.json records of the dataset exported."""
    fingerprint = ds.attrs.get("fingerprint")
    return {
        "format": EXPORT_FORMAT,
        "dataset": str(ds.path.parent),
        "fingerprint": fingerprint,
        "n_samples": len(ds),
    }


def claim_export_folder(out: Path, record: dict) -> bool:
    """Make ``out`` the export folder of ``record``'s dataset: True when resuming its export.

    A new or empty folder gets ``export.json``; one whose ``export.json`` names the same dataset
    (fingerprint and sample count) is resumed; any other non-empty folder is a DataError naming
    both datasets or the files found, before anything is written."""
    if out.is_dir() and any(out.iterdir()):
        try:
            held = json.loads((out / MARKER).read_text(encoding="utf-8"))
        except (OSError, ValueError):
            shown = ", ".join(sorted(p.name for p in out.iterdir())[:5])
            raise DataError(
                f"--out {out} is not empty ({shown}, ...) and holds no {MARKER}: not an export "
                f"of {record['dataset']}; nothing would be kept apart. Fix: an empty or new --out"
            ) from None
        same = all(held.get(k) == record[k] for k in ("fingerprint", "n_samples"))
        if not same or record["fingerprint"] is None:
            raise DataError(
                f"--out {out} holds the export of {held.get('dataset')} (fingerprint "
                f"{str(held.get('fingerprint'))[:12]}), not of {record['dataset']} (fingerprint "
                f"{str(record['fingerprint'])[:12]}); the two would mix. Fix: another --out"
            )
        return True
    out.mkdir(parents=True, exist_ok=True)
    with atomic_path(out / MARKER) as tmp:
        tmp.write_text(json.dumps(record, indent=2) + "\n", encoding="utf-8")
    return False


def export_png(
    dataset_dir: str | Path, out_dir: str | Path, *, progress: bool = False
) -> dict[str, int]:
    """Write every sample's tactile image (and hand label image) as PNG under ``out_dir``.

    progress : show a progress bar over the samples. Returns {folder: number of PNG files of the
    export} for the folders used (files kept from an earlier, interrupted export included).
    ``out_dir`` is refused unless new, empty or this dataset's export (`claim_export_folder`).
    """
    ds = open_dataset(dataset_dir)
    out = Path(out_dir)
    actions = ds.attrs.get("actions", [])
    actions = actions if isinstance(actions, list) else []
    written: dict[str, int] = {}
    with ds:
        with writing(out / MARKER):
            claim_export_folder(out, export_record(ds))
        for folder in FOLDERS:
            remove_stale(out / folder)  # temporary PNGs of a killed export
        for i in tqdm(range(len(ds)), unit="sample", disable=not progress, dynamic_ncols=True):
            stem = sample_stem(ds, i, actions)
            for folder, picture in _pictures(ds, i):
                path = out / folder / f"{stem}.png"
                if not path.is_file():
                    with writing(path, fix="free space there and export again: it resumes"):
                        path.parent.mkdir(parents=True, exist_ok=True)
                        save_png(path, picture())
                written[folder] = written.get(folder, 0) + 1
    return written


def _pictures(ds: DatasetReader, i: int) -> list[tuple[str, object]]:
    """(folder, function returning the picture) pairs of sample ``i`` (read only if needed)."""
    image = lambda: ds.image[i]  # noqa: E731
    if "is_hand" not in ds.fields:
        return [("unlabelled", image)]
    if int(ds.is_hand[i]) == 0:
        return [("non_hand", image)]
    pictures = [("hand", image)]
    if "label_image" in ds.fields:
        pictures.append(("labels", lambda: colorize(ds.label_image[i])))
    return pictures
