"""Export a dataset as PNG folders, like the paper's supplementary material.

    OUT/hand/000012_subject3_grasp.png       grey tactile image (H, W) of a hand sample
    OUT/non_hand/000013_instance5.png        grey tactile image of a non-hand sample
    OUT/labels/000012_subject3_grasp.png     RGB label image of a hand sample (tactile.PALETTE)
    OUT/unlabelled/000014.png                images of a dataset without ``is_hand``

File names start with the sample index (6 digits), so they sort in dataset order.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from PIL import Image
from tqdm import tqdm

from tactile.dataset.reader import DatasetReader, open_dataset
from tactile.labels import colorize

FOLDERS = ("hand", "non_hand", "labels", "unlabelled")


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
    """Write an (H, W) uint8 grey or (H, W, 3) uint8 RGB image as PNG."""
    Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8)).save(path, format="PNG")


def export_png(
    dataset_dir: str | Path, out_dir: str | Path, *, progress: bool = False
) -> dict[str, int]:
    """Write every sample's tactile image (and hand label image) as PNG under ``out_dir``.

    progress : show a progress bar over the samples. Returns {folder: number of files written}
    for the folders used.
    """
    ds = open_dataset(dataset_dir)
    out = Path(out_dir)
    actions = ds.attrs.get("actions", [])
    actions = actions if isinstance(actions, list) else []
    written: dict[str, int] = {}
    with ds:
        for i in tqdm(range(len(ds)), unit="sample", disable=not progress, dynamic_ncols=True):
            for folder, image in _pictures(ds, i):
                (out / folder).mkdir(parents=True, exist_ok=True)
                save_png(out / folder / f"{sample_stem(ds, i, actions)}.png", image)
                written[folder] = written.get(folder, 0) + 1
    return written


def _pictures(ds: DatasetReader, i: int) -> list[tuple[str, np.ndarray]]:
    """(folder, picture) pairs of sample ``i``."""
    image = ds.image[i]
    if "is_hand" not in ds.fields:
        return [("unlabelled", image)]
    if int(ds.is_hand[i]) == 0:
        return [("non_hand", image)]
    pictures = [("hand", image)]
    if "label_image" in ds.fields:
        pictures.append(("labels", colorize(ds.label_image[i])))
    return pictures
