"""The same presses on skins of different taxel density: image, truth and a segmenter's labels.

    python docs/density_prints.py data/forearm:runs/seg/best.pt \
        data/forearm_x4:runs/seg_x4/best.pt --png docs/density_prints.png [--n 5] [--seed 0]

Each argument is ``DATASET:SEGMENTER`` (a dataset folder and a segmenter checkpoint trained on
it). The script picks ``--n`` hand samples that are in every dataset's test split and are the
same press in all (same episode seed and subject: same person, hand and press plan; each skin
draws its own aim, so the print lies elsewhere on each map; `docs/common_test_samples.py`),
drawn with ``--seed``, and draws one row per press: for each skin the tactile image (1 mm per
pixel), its label image and the segmenter's labels (`learn.predict.segment`, the `handskin
predict` path), titled with that image's mIoU on the map grid (Long et al., classes in the
truth or the prediction). Each image is cropped to the box of the print, grown by 15 mm.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from common_test_samples import press_keys  # docs/, beside this script

from learn.metrics import confusion_matrix, segmentation_scores
from learn.predict import load_predictor, segment
from tactile.dataset import open_dataset
from tactile.labels import CLASS_NAMES, PALETTE

MARGIN_PX = 15  # crop margin around the print, map pixels (1 mm)


def press_table(data: Path) -> tuple[np.ndarray, np.ndarray, set[int]]:
    """(S, 2) int64 press keys (`common_test_samples.press_keys`: what makes two samples the
    same press), (S,) bool is-hand, and the test indices."""
    with open_dataset(data) as ds:
        hand = np.asarray(ds.file["samples/is_hand"][:]).astype(bool)
        test = {int(i) for i in ds.file["splits/test"][:]}
    return press_keys(data), hand, test


def common_hands(datasets: list[Path], n: int, seed: int) -> list[int]:
    """``n`` sample indices (seeded draw, sorted) that are test hands of every dataset and the
    same press in all of them."""
    tables = [press_table(d) for d in datasets]
    size = min(len(t[0]) for t in tables)
    first = tables[0][0][:size]
    ok = tables[0][1][:size] & np.all([t[0][:size] == first for t in tables], axis=(0, 2))
    both = np.flatnonzero(ok & np.array([all(i in t[2] for t in tables) for i in range(size)]))
    if len(both) < n:
        raise SystemExit(f"only {len(both)} test hands are common to all datasets; ask for fewer")
    return sorted(np.random.default_rng(seed).choice(both, n, replace=False).tolist())


def crop(*images: np.ndarray) -> tuple[slice, slice]:
    """Rows and columns of the first image's non-zero box grown by `MARGIN_PX`."""
    r, c = np.flatnonzero(images[0].any(1)), np.flatnonzero(images[0].any(0))
    h, w = images[0].shape
    return (
        slice(max(r[0] - MARGIN_PX, 0), min(r[-1] + MARGIN_PX + 1, h)),
        slice(max(c[0] - MARGIN_PX, 0), min(c[-1] + MARGIN_PX + 1, w)),
    )


def image_miou(truth: np.ndarray, pred: np.ndarray) -> float:
    cm = confusion_matrix(*(np.asarray(a, np.int64) for a in (truth, pred)), len(CLASS_NAMES))
    return 100 * segmentation_scores(cm)["mean_iou"]


def draw(pairs: list[tuple[Path, Path]], indices: list[int], png: Path) -> Path:
    """One row per sample; three panels per skin."""
    import torch

    fig, axes = plt.subplots(
        len(indices),
        3 * len(pairs),
        squeeze=False,
        figsize=(2.2 * 3 * len(pairs), 2.1 * len(indices)),
    )
    for k, (data, ckpt) in enumerate(pairs):
        seg = load_predictor(ckpt)
        with open_dataset(data) as ds:
            name = ds.attrs.get("part", data.name)
            for row, i in enumerate(indices):
                image, truth = ds.file["samples/image"][i], ds.file["samples/label_image"][i]
                pred = segment(image, seg)
                box = crop(image)
                miou = image_miou(torch.from_numpy(truth), torch.from_numpy(pred))
                panels = (
                    (image, "gray", f"{name} #{i}"),
                    (PALETTE[truth], None, "truth"),
                    (PALETTE[pred], None, f"{ckpt.parent.name}: {miou:.0f} % mIoU"),
                )
                for j, (img, cmap, title) in enumerate(panels):
                    ax = axes[row, 3 * k + j]
                    ax.imshow(img[box], cmap=cmap, interpolation="nearest")
                    ax.set_title(title, fontsize=7)
                    ax.axis("off")
    handles = [plt.Rectangle((0, 0), 1, 1, color=PALETTE[c] / 255) for c in range(1, 7)]
    fig.legend(handles, CLASS_NAMES[1:], loc="lower center", ncol=6, fontsize=8)
    fig.suptitle(
        "The same presses on each skin: tactile image, true parts, segmenter "
        "(crops of the 1 mm map)",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, 0.04, 1, 0.97))
    fig.savefig(png, dpi=90)
    return png


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("pairs", nargs="+", help="DATASET:SEGMENTER (dataset folder, checkpoint)")
    ap.add_argument("--png", type=Path, required=True, help="figure to write (PNG path)")
    ap.add_argument("--n", type=int, default=5, help="presses to draw (count)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the draw of presses")
    args = ap.parse_args()
    pairs = [tuple(Path(p) for p in pair.split(":", 1)) for pair in args.pairs]
    if any(len(p) != 2 for p in pairs):
        raise SystemExit("give each skin as DATASET:SEGMENTER")
    indices = common_hands([d for d, _ in pairs], args.n, args.seed)
    print(f"presses {indices}; figure written to {draw(pairs, indices, args.png)}")


if __name__ == "__main__":
    main()
