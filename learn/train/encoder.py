"""A segmenter started from the encoder of a hand / non-hand classifier trained first on the same
data (``handskin train DATA --out OUT --arch segnet``).

The paper's SegNet and FCN-16s start from VGG16's ImageNet weights, which do not fit a one-channel
tactile network of a quarter of VGG16's width. The nearest thing is our own VGG16 classifier:
trained on every training image of the dataset (hands, and the objects and body parts that are
not), its ``encoder.*`` is the segmenter's, so it loads as is and the decoder starts fresh. On
the paper-sized forearm set it lifted SegNet w0.25 by +2.5 to +7.9 mIoU points (mean +6.1 over
three seeds) over the same seed from scratch (docs/findings.md).

    ckpt = pretrain_encoder(run, "data/paper", Path("runs/segnet"))   # runs/segnet/vgg16/best.pt

The classifier is the vgg16 preset at the segmenter's width, input size, canvas, seed, number
format and device: 20 epochs, lr x 0.2 after 14. It is trained into ``OUT/vgg16``; a finished
one there is reused and a stopped one resumed (`learn.train.runs.train_once`). ``handskin
train`` does this by default for a segmenter on a handskin dataset (:func:`wanted`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from learn.config import preset_run
from learn.data.load import is_dataset, load_data
from learn.train.checkpoint import BEST, LAST, load_checkpoint
from learn.train.runs import train_once

#: the segmenters whose encoder is VGG16's (its ``encoder.*`` names and shapes)
VGG_SEGMENTERS = ("segnet", "fcn16s")

#: the classifier's schedule (epochs, lr drop period in epochs; docs/findings.md)
CLASSIFIER_EPOCHS, CLASSIFIER_DROP_EPOCHS = 20, 14
FOLDER = "vgg16"  # the classifier's run folder inside the segmenter's


def encoder_run(run):
    """The classifier's RunConfig for segmenter run ``run``: the vgg16 preset with ``run``'s
    width, input channels, input size (px), canvas (mm), seed, validation share, views, threads,
    number format and device; 20 epochs with lr x 0.2 after 14."""
    vgg = preset_run(
        "vgg16",
        device=run.device,
        seed=run.train.seed,
        epochs=CLASSIFIER_EPOCHS,
        lr_drop_period_epochs=CLASSIFIER_DROP_EPOCHS,
    )
    model = dataclasses.replace(
        vgg.model,
        width=run.model.width,
        input_size=run.model.input_size,
        in_channels=run.model.in_channels,
        canvas_mm=run.model.canvas_mm,
    )
    return dataclasses.replace(
        vgg,
        model=model,
        val_fraction=run.val_fraction,
        flips=run.flips,
        threads=run.threads,
        precision=run.precision,
    )


def wanted(
    from_scratch: bool,
    run,
    data: str | Path,
    init: Path | None,
    cv_grid: str | None,
    out: Path,
    resume: bool,
) -> bool:
    """Whether ``handskin train`` starts ``run`` from a classifier's encoder: not with
    ``--from-scratch``; otherwise for a segmenter on a handskin dataset without ``--init`` or
    ``--cv-grid`` (the classifier would see every fold's people), and on ``--resume`` as the run
    in ``out`` started."""
    if from_scratch or run.model.arch not in VGG_SEGMENTERS or init is not None or cv_grid:
        return False
    if not is_dataset(data):  # an image folder has no non-hand images to learn a classifier
        return False
    last = Path(out) / LAST
    if resume and last.is_file():
        return load_checkpoint(last).get("init") == str(Path(out) / FOLDER / BEST)
    return True


def pretrain_encoder(run, data: str | Path, out: Path, progress: bool = True) -> Path:
    """``out/vgg16/best.pt``: the classifier of :func:`encoder_run` trained on ``data`` (reused
    when finished there, resumed when stopped)."""
    vgg = encoder_run(run)
    return train_once(
        Path(out) / FOLDER,
        vgg,
        lambda: load_data(data, vgg, with_test=False, progress=progress),
        progress=progress,
        data=data,
    )[0]
