"""Do two segmenters make different mistakes? Score the mean of their softmax on the test hands.

    python docs/check_ensemble.py DATASET CHECKPOINT CHECKPOINT [...] [--no-tta]

Each segmenter runs with test-time flips over the views it was trained on (`learn.tta`,
`learn.evaluate.tta_views`) unless ``--no-tta``; the class probabilities of all of them are
averaged per pixel, unpressed pixels are background (`learn.inputs.unpressed_as_background`,
as in ``handskin evaluate``), and the mIoU is computed from the pooled confusion matrix. Prints
each segmenter's own mIoU first (these match ``handskin evaluate --tta``'s rows), then the
mean's. The time per image of the mean is about the sum of the members' (the report's rows).
"""

from __future__ import annotations

import argparse

import torch

from learn import metrics as M
from learn.checkpoint import load_checkpoint, model_from_checkpoint
from learn.evaluate import logits_of, scores, tta_views
from learn.folder import materialize, open_split
from learn.inputs import unpressed_as_background
from learn.tta import FlipTTA


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data", help="handskin dataset folder")
    ap.add_argument("checkpoints", nargs="+", help="segmenter checkpoints (.pt), two or more")
    ap.add_argument("--no-tta", action="store_true", help="score without test-time flips")
    args = ap.parse_args()
    torch.set_num_threads(2)
    members, sizes = [], set()
    for path in args.checkpoints:
        model, run = model_from_checkpoint(load_checkpoint(path))
        if run.task != "segment":
            raise SystemExit(f"{path} is a classifier; give segmenter checkpoints")
        members.append(model if args.no_tta else FlipTTA(model, tta_views(run, path)))
        sizes.add(tuple(run.model.input_size))
    if len(sizes) != 1:
        raise SystemExit(f"the segmenters take different input sizes {sorted(sizes)}; give ones "
                         "trained at one size")  # fmt: skip
    split = open_split(args.data, "test", "segment", sizes.pop(), None, run.train.seed)
    test = materialize(split, "test", progress=False)
    probs = [logits_of(model, test.x).softmax(1) for model in members]
    rows = [*zip(args.checkpoints, probs, strict=True), ("mean of all", sum(probs) / len(probs))]
    flips = "off" if args.no_tta else "on"
    print(f"{len(test.x)} test images of {args.data}; test-time flips {flips}")
    for name, p in rows:
        pred = unpressed_as_background(p.argmax(1), test.x)
        cm = M.confusion_matrix(test.y, pred, run.model.num_classes)
        print(f"  mIoU {100 * scores(cm)['mean_iou']:6.2f} %  {name}")


if __name__ == "__main__":
    main()
