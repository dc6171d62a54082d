"""Can fingers be told apart by the shape of the print alone? Two measures on the test hands.

    python docs/check_finger_blobs.py DATASET [--limit N]

1. *Shared blobs*: the share of each finger's labelled pixels that lie in a pressed blob
   (8-connected pixels with grey > 0) that also holds another finger (the palm not counted),
   on the map grid (1 mm per pixel) and on the segmenter's input (68 x 100, `learn.inputs`).
   Near 100 % means the fingers of a print touch each other in the image, so a segmenter must
   place the borders inside a blob and cannot count blobs to name fingers.
2. *Border valleys*: on the map grid, the mean grey level of pixels on a border between two
   fingers (a 4-neighbour labelled another finger) over the mean grey level inside fingers,
   per image. Below 1 the pressure dips between fingers, so the borders are visible in the
   image; which finger is which must then come from the print's layout.

numpy and scipy only; reads the dataset's stored images and label images.
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy import ndimage

from learn.inputs import net_input
from tactile.dataset.reader import open_dataset
from tactile.labels import CLASS_NAMES
from tactile.resize import NET_SIZE, resize_labels

FINGERS = range(1, 6)  # thumb .. pinkie (`tactile.labels.CLASS_NAMES`); 6 is the palm


def shared_blob_pixels(image: np.ndarray, labels: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per finger 1..5: (labelled pixels, of them in a blob holding another finger), (5,) each.
    image (H, W) grey (> 0 where pressed); labels (H, W) class ids."""
    blobs, n = ndimage.label(image > 0, structure=np.ones((3, 3)))
    finger = (labels >= 1) & (labels <= 5)
    # fingers per blob: count of distinct finger ids among each blob's pixels
    pairs = np.unique(np.stack([blobs[finger], labels[finger]]), axis=1)
    fingers_in_blob = np.bincount(pairs[0], minlength=n + 1)
    fingers_in_blob[0] = 0  # unpressed pixels are no blob
    total, shared = np.zeros(5, np.int64), np.zeros(5, np.int64)
    for c in FINGERS:
        ids = blobs[labels == c]
        total[c - 1] = ids.size
        shared[c - 1] = int((fingers_in_blob[ids] > 1).sum())
    return total, shared


def border_ratio(image: np.ndarray, labels: np.ndarray) -> float:
    """Mean grey on finger-finger borders over mean grey inside fingers (NaN: no border)."""
    finger = (labels >= 1) & (labels <= 5)
    border = np.zeros_like(finger)
    for a, b in (
        ((slice(None), slice(None, -1)), (slice(None), slice(1, None))),
        ((slice(None, -1), slice(None)), (slice(1, None), slice(None))),
    ):
        meet = finger[a] & finger[b] & (labels[a] != labels[b])
        border[a] |= meet
        border[b] |= meet
    inside = finger & ~border
    if border.sum() < 5 or inside.sum() < 5:
        return float("nan")
    grey = image.astype(np.float64)
    return float(grey[border].mean() / grey[inside].mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", help="handskin dataset folder")
    ap.add_argument("--limit", type=int, default=None, help="first N test hands only (count)")
    args = ap.parse_args()
    ds = open_dataset(args.data)
    test = np.sort(ds.splits["test"])
    hands = test[np.asarray(ds.is_hand[:])[test] == 1][: args.limit]
    grid, net = np.zeros((2, 5), np.int64), np.zeros((2, 5), np.int64)
    ratios = []
    for i in hands:
        image, labels = ds.image[i], ds.label_image[i]
        grid += shared_blob_pixels(image, labels)
        x = net_input(image.astype(np.float32) / 255.0, NET_SIZE, "segment")
        net += shared_blob_pixels(x, resize_labels(labels, NET_SIZE))
        ratios.append(border_ratio(image, labels))
    print(f"{len(hands)} test hands of {args.data}")
    print(
        "finger pixels in a blob shared with another finger, %: map grid (1 mm) / "
        f"{NET_SIZE[0]} x {NET_SIZE[1]} input"
    )
    pct_grid = 100 * grid[1] / np.maximum(grid[0], 1)
    pct_net = 100 * net[1] / np.maximum(net[0], 1)
    for c in FINGERS:
        print(f"  {CLASS_NAMES[c]:7s} {pct_grid[c - 1]:5.1f} / {pct_net[c - 1]:5.1f}")
    r = np.array(ratios)
    r = r[~np.isnan(r)]
    q1, med, q3 = np.percentile(r, [25, 50, 75])
    print(
        f"border / inside-finger grey level, {r.size} images with a finger-finger border: "
        f"median {med:.2f} (quartiles {q1:.2f}-{q3:.2f}); below 0.7 on "
        f"{100 * np.mean(r < 0.7):.0f} % of images"
    )


if __name__ == "__main__":
    main()
