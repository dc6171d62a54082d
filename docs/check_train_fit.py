"""Does a network fit its own training images? Accuracy (classifiers) or mean IoU (segmenters)
on train, validation and test.

    python docs/check_train_fit.py DATASET CHECKPOINT [CHECKPOINT ...] [--tta]

For each checkpoint (``handskin train``'s best.pt) the dataset is split as its run split it
(the run's seed and validation share: the training images are the ones it learned from), and
the network scores every image of each part in eval mode (no dropout, batch-norm statistics
frozen), in the original view, or with ``--tta`` averaged over the paper's three views
(`learn.tta`); a segmenter's mean IoU is over each part's pixels pooled (`learn.metrics`, as
``handskin evaluate`` scores). A network whose training score sits near its test score
underfits: more data or a better teacher cannot lift it beyond what it can fit. For a
checkpoint trained with a teacher (``distill_from``), the teacher is scored too.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import torch

from learn.checkpoint import load_checkpoint, model_from_checkpoint
from learn.evaluate import evaluate_tensors
from learn.train import load_data
from learn.tta import PAPER_VIEWS, FlipTTA


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", type=Path, help="dataset folder the checkpoints were trained on")
    ap.add_argument("checkpoints", type=Path, nargs="+", help="best.pt files of handskin train")
    ap.add_argument("--tta", action="store_true", help="average over the paper's three views")
    args = ap.parse_args()
    torch.set_num_threads(2)
    print("| network | score | train | validation | test |\n|---|---|---|---|---|")
    for path in args.checkpoints:
        model, run = model_from_checkpoint(load_checkpoint(path))
        data = load_data(args.data, run, progress=False)
        nets = [(str(path), model)]
        if run.distill_from:
            nets.append(
                (
                    f"its teacher {run.distill_from}",
                    model_from_checkpoint(load_checkpoint(run.distill_from))[0],
                )
            )
        for name, net in nets:
            net = FlipTTA(net.eval(), PAPER_VIEWS) if args.tta else net.eval()
            key = "accuracy" if run.task == "classify" else "mean_iou"
            cells = [
                evaluate_tensors(net, part, run.model.num_classes).metrics[key]
                for part in (data.train, data.val, data.test)
            ]
            print(f"| {name} | {key} | " + " | ".join(f"{100 * c:.2f} %" for c in cells) + " |")


if __name__ == "__main__":
    main()
