"""A segmenter started from the encoder of a hand / non-hand classifier trained first on the same
data (``handskin train DATA --out OUT --arch segnet --pretrain-encoder``).

The paper's SegNet and FCN-16s start from VGG16's ImageNet weights, which cannot be downloaded
here. The nearest thing is our own VGG16 classifier: trained on every training image of the
dataset (hands and the objects and body parts that are not), its ``encoder.*`` is the
segmenter's, so it loads as is and the decoder starts fresh. On the paper-sized forearm set
it lifted SegNet w0.25 by +2.5 to +7.9 mIoU points (mean +6.1 over three seeds) over the same
seed from scratch
(docs/learning.md, "An encoder from our own classifier").

    ckpt = pretrain_encoder(run, "data/paper", Path("runs/segnet"))   # runs/segnet/vgg16/best.pt

The classifier is the vgg16 preset at the segmenter's width, input size, canvas, seed, number
format and device, with that study's schedule: 20 epochs, lr x 0.2 after 14 (6.2 min on 2
cores for the paper-sized set). It is trained into ``OUT/vgg16``; a finished one there is
reused and a stopped one resumed (`learn.experiments.models.train_once`). ``handskin train``
does this by default for a segmenter on a handskin dataset (:func:`wanted`).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from learn.checkpoint import BEST, LAST, load_checkpoint
from tactile.errors import ConfigError

#: the classifier's schedule (epochs, lr drop period in epochs), as measured in docs/learning.md
CLASSIFIER_EPOCHS, CLASSIFIER_DROP_EPOCHS = 20, 14
FOLDER = "vgg16"  # the classifier's run folder inside the segmenter's


def encoder_run(run):
    """The classifier's RunConfig for segmenter run ``run``: the vgg16 preset with ``run``'s
    width, input channels, input size (px), canvas (mm), seed, validation share, views, threads,
    number format and device; 20 epochs with lr x 0.2 after 14."""
    from learn.experiments.models import preset_run

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
        rot180=run.rot180,
        threads=run.threads,
        precision=run.precision,
    )


def wanted(
    flag: bool | None,
    run,
    data: str | Path,
    init: Path | None,
    cv_grid: str | None,
    out: Path,
    resume: bool,
) -> bool:
    """Whether ``handskin train`` starts ``run`` from a classifier's encoder: ``flag``
    (``--pretrain-encoder`` / ``--no-pretrain-encoder``) when given; by default yes for a
    segmenter on a handskin dataset without ``--init`` or ``--cv-grid``, and when resuming, as
    the run in ``out`` started. ConfigError for ``--pretrain-encoder`` on a ``--resume`` of a
    run that started otherwise (the other checks: :func:`check_pretrain`)."""
    from learn.folder import is_dataset

    if flag is False:
        return False
    if flag is None and (
        run.task != "segment" or init is not None or cv_grid or not is_dataset(data)
    ):
        return False
    started = _started(out, resume)  # reads out/last.pt once, when resuming
    if flag and started is False:
        raise ConfigError(
            f"--resume: the run in {out} did not start from {out / FOLDER}'s "
            "encoder. Fix: resume it with --no-pretrain-encoder"
        )
    return bool(flag) or started in (None, True)


def _started(out: Path, resume: bool) -> bool | None:
    """For ``--resume`` of a run in ``out``: whether it started from ``out/vgg16``'s encoder
    (None when there is no run to resume)."""
    last = Path(out) / LAST
    if not (resume and last.is_file()):
        return None
    return load_checkpoint(last).get("init") == str(Path(out) / FOLDER / BEST)


def check_pretrain(run, data: str | Path, init: Path | None, cv_grid: str | None) -> None:
    """ConfigError, before any work, when ``--pretrain-encoder`` cannot apply: a classifier run,
    a start given with ``--init`` too, an image folder (no non-hand images to learn the
    classifier from), or a cross-validation (the classifier sees every fold's people)."""
    from learn.folder import is_dataset

    if run.task != "segment":
        raise ConfigError(
            f"--pretrain-encoder starts a segmenter (segnet, fcn16s), not a "
            f"{run.model.arch}. Fix: remove it, or --arch segnet"
        )
    if init is not None:
        raise ConfigError(
            "--pretrain-encoder trains the start that --init would give. Fix: give one of the two"
        )
    if not is_dataset(data):
        raise ConfigError(
            f"--pretrain-encoder needs a handskin dataset (hands and non-hands for "
            f"the classifier); {data} is an image folder. Fix: train a vgg16 on "
            "a classification folder and give its best.pt as --init"
        )
    if cv_grid:
        raise ConfigError(
            "--pretrain-encoder with --cv-grid: the classifier trained on every "
            "fold's validation people, so the folds would not be held out. Fix: "
            "cross-validate from scratch, then train the pick with the encoder"
        )


def pretrain_encoder(run, data: str | Path, out: Path, progress: bool = True) -> Path:
    """``out/vgg16/best.pt``: the classifier of :func:`encoder_run` trained on ``data`` (reused
    when finished there, resumed when stopped)."""
    from learn.experiments.models import train_once
    from learn.train import load_data

    vgg = encoder_run(run)
    return train_once(
        Path(out) / FOLDER, vgg, lambda: load_data(data, vgg, progress=progress), progress=progress
    )[0]
