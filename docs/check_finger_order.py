"""Does a segmenter read the finger order backwards? A per-image test of the mirror hypothesis.

    python docs/check_finger_order.py CHECKPOINT DATASET

For every test hand image, the prediction is scored against the true labels and against the
labels with the finger order reversed (index <-> pinkie, middle <-> ring; thumb and palm kept),
and the better of the two is kept. If mirror-image confusions came from whole prints read the
wrong way round, this "best of both orders" mIoU would be far above the plain one; if they come
from single fingers, the two stay close. Prints both, the share of images where the reversed
order scores better (with and without the thumb in the print), and per-class IoU.
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from learn import metrics as M
from learn.checkpoint import load_checkpoint, model_from_checkpoint
from learn.data import TorchTactileDataset
from learn.evaluate import evaluate_tensors
from learn.folder import materialize

REVERSED = torch.tensor([0, 1, 5, 4, 3, 2, 6])  # background, thumb, index..pinkie reversed, palm


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("checkpoint", help="segmenter checkpoint (.pt)")
    ap.add_argument("data", help="handskin dataset folder")
    args = ap.parse_args()
    torch.set_num_threads(2)
    model, run = model_from_checkpoint(load_checkpoint(args.checkpoint))
    ds = TorchTactileDataset(
        args.data, split="test", task="segment", size=run.model.input_size, flips=False
    )
    test = materialize(ds, progress=False)
    pred = evaluate_tensors(model, test, 7, keep_predictions=True).predictions
    plain, best = torch.zeros(7, 7, dtype=torch.long), torch.zeros(7, 7, dtype=torch.long)
    reversed_better, thumb = [], []
    for y, p in zip(test.y, pred, strict=True):
        a = M.confusion_matrix(y[None], p[None], 7)
        b = M.confusion_matrix(REVERSED[y][None], p[None], 7)
        flip = int(torch.diag(b)[1:].sum()) > int(torch.diag(a)[1:].sum())
        plain += a
        best += b if flip else a
        reversed_better.append(flip)
        thumb.append(bool((y == 1).any()))
    rb, th = np.array(reversed_better), np.array(thumb)
    print(
        f"{len(rb)} test hand images; reversed order scores better on {rb.mean():.1%} "
        f"(thumb in the print: {rb[th].mean():.1%} of {th.sum()}; "
        f"without: {rb[~th].mean():.1%} of {(~th).sum()})"
    )
    for name, cm in (("as labelled", plain), ("best of both orders per image", best)):
        iou = M.class_ious(cm)
        print(
            f"{name}: mIoU {100 * M.mean_iou(cm):.2f} %; IoU per class (%) "
            f"{np.round(100 * iou.numpy(), 1).tolist()}"
        )


if __name__ == "__main__":
    main()
