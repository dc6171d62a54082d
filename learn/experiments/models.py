"""Trained models for experiments: a given checkpoint, or one trained here once and reused.

    ckpt = ensure_model("handsnet", "out/forearm", out / "models", epochs=8)   # -> Path to .pt

A model trained by an experiment lives in ``models_dir/<arch>/best.pt`` with its ``run.toml``;
a later call with the same folder reuses it (and says so) instead of training again, so the
robustness, pareto and fault-aware experiments can share one set of models.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from tactile.errors import ConfigError, DataError


def preset_run(arch: str, **train_changes: object):
    """The ``learn.config`` preset of ``arch`` as a RunConfig, with TrainConfig fields changed."""
    from learn import config as C
    from learn.train import RunConfig, replace_train

    presets = {"handsnet": C.HANDSNET, "vgg16": C.VGG16_FINETUNE, "segnet": C.SEGNET,
               "fcn16s": C.FCN16S}  # fmt: skip
    if arch not in presets:
        raise ConfigError(f"unknown arch {arch!r}; choose one of: {', '.join(presets)}")
    run = RunConfig(model=presets[arch].model, train=presets[arch].train)
    changes = {k: v for k, v in train_changes.items() if v is not None}
    return replace_train(run, **changes) if changes else run


def ensure_model(
    arch: str,
    data: str | Path,
    models_dir: str | Path,
    *,
    checkpoint: str | Path | None = None,
    run=None,
    epochs: int | None = None,
    seed: int = 0,
    progress: bool = True,
    name: str | None = None,
) -> Path:
    """Path of a trained checkpoint of ``arch`` for dataset ``data``.

    checkpoint : use this .pt file as is (checked to exist).
    run : a ``learn.train.RunConfig`` to train with (default: the arch's preset, with ``epochs``
    and ``seed`` changed when given). The model is trained into ``models_dir/<name or arch>`` and
    reused when ``best.pt`` is already there.
    """
    from learn.train import fit, load_data

    if checkpoint is not None:
        checkpoint = Path(checkpoint)
        if not checkpoint.is_file():
            raise DataError(f"no checkpoint at {checkpoint}. Fix: a .pt file from handskin train")
        return checkpoint
    out = Path(models_dir) / (name or arch)
    run = run if run is not None else preset_run(arch, epochs=epochs, seed=seed)
    if run.model.arch != arch:
        run = dataclasses.replace(run, model=dataclasses.replace(run.model, arch=arch))
    if (out / "best.pt").is_file():
        check_reusable(out / "best.pt", run)
        print(f"reusing {out / 'best.pt'}")
        return out / "best.pt"
    fit(run, load_data(data, run, progress=progress), out, progress=progress)
    return out / "best.pt"


def check_reusable(path: Path, run) -> None:
    """ConfigError unless the checkpoint at ``path`` (when there is one) was trained with
    ``run``'s configuration."""
    from learn.checkpoint import check_inputs, load_checkpoint
    from learn.train import run_from_dict

    if not path.is_file():
        return
    ckpt = load_checkpoint(path)
    stored = run_from_dict(ckpt["config"])
    check_inputs(ckpt, stored.task, str(path))
    if stored != run:
        raise ConfigError(
            f"{path} was trained with another configuration than this experiment asks for "
            f"(stored {stored.model.arch} {stored.train}, asked {run.model.arch} {run.train}). "
            "Fix: give another --models folder, or delete that folder to retrain"
        )
