"""Trained models for experiments: a given checkpoint, or one trained here once and reused.

    ckpt = ensure_model("handsnet", "out/forearm", out / "models", epochs=8)   # -> Path to .pt

A model trained by an experiment lives in ``models_dir/<arch>/best.pt`` with its ``run.toml``;
a later call with the same folder reuses it (and says so) instead of training again, so the
robustness, pareto and fault-aware experiments can share one set of models.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

from tactile.errors import ConfigError, DataError

#: ``--device`` of the experiments that train networks.
DEVICE_HELP = (
    "Where the networks trained here train: cpu (the default) or cuda / cuda:N (a GPU, "
    "with a CUDA build of torch). Networks already in the models folder are reused "
    "wherever they trained; times per image are measured on the CPU either way; "
    "no unit."
)


def preset_run(arch: str, *, device: str = "cpu", **train_changes: object):
    """The ``learn.config`` preset of ``arch`` as a RunConfig training on ``device`` ("cpu",
    "cuda", "cuda:N"), with TrainConfig fields changed."""
    from learn import config as C
    from learn.train import RunConfig, replace_train

    if arch not in C.PRESET_OF_ARCH:
        raise ConfigError(f"unknown arch {arch!r}; choose one of: {', '.join(C.PRESET_OF_ARCH)}")
    preset = C.PRESET_OF_ARCH[arch]
    run = RunConfig(model=preset.model, train=preset.train, device=device)
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
    device: str = "cpu",
) -> Path:
    """Path of a trained checkpoint of ``arch`` for dataset ``data``.

    checkpoint : use this .pt file as is (checked to exist).
    run : a ``learn.train.RunConfig`` to train with (default: the arch's preset on ``device``,
    with ``epochs`` and ``seed`` changed when given). The model is trained into
    ``models_dir/<name or arch>`` and reused when ``best.pt`` is already there, wherever it
    trained.
    """
    from learn.train import load_data

    if checkpoint is not None:
        checkpoint = Path(checkpoint)
        if not checkpoint.is_file():
            raise DataError(f"no checkpoint at {checkpoint}. Fix: a .pt file from handskin train")
        return checkpoint
    out = Path(models_dir) / (name or arch)
    run = run if run is not None else preset_run(arch, epochs=epochs, seed=seed, device=device)
    if run.model.arch != arch:
        run = dataclasses.replace(run, model=dataclasses.replace(run.model, arch=arch))
    return train_once(out, run, lambda: load_data(data, run, progress=progress), progress=progress)[
        0
    ]


def finished(out_dir: str | Path, run) -> bool:
    """True when ``out_dir/last.pt`` ends ``run``: its schedule's last epoch is done, or
    patience stopped it; False for a stopped (paused or killed) run, and without last.pt."""
    from learn.checkpoint import LAST, load_checkpoint
    from learn.run_state import patience_out

    last = Path(out_dir) / LAST
    if not last.is_file():
        return False
    ckpt = load_checkpoint(last)
    return int(ckpt["epoch"]) >= run.train.epochs or patience_out(list(ckpt["history"]), run)


def train_once(
    out: Path,
    run,
    make_data: Callable[[], object],
    *,
    init_from: str | Path | None = None,
    progress: bool = True,
) -> tuple[Path, bool]:
    """(``out/best.pt``, whether this call trained) for ``run`` trained into ``out``.

    A finished run there is reused (and said so); a stopped one (killed, or paused mid-schedule)
    resumes from its ``last.pt``, so a long experiment interrupted mid-training neither restarts
    that model nor takes its half-trained weights as done; else ``make_data()`` is trained on.
    ConfigError, before any work, when ``out`` holds a run of another configuration.
    """
    from learn.checkpoint import BEST, LAST
    from learn.train import fit

    last, best = out / LAST, out / BEST
    check_reusable(last if last.is_file() else best, run)
    if best.is_file() and (not last.is_file() or finished(out, run)):
        print(f"reusing {best}")
        return best, False
    if last.is_file():
        print(f"resuming the stopped run in {out}")
    fit(run, make_data(), out, resume=True, init_from=init_from, progress=progress)
    return best, True


def check_reusable(path: Path, run) -> None:
    """ConfigError unless the checkpoint at ``path`` (when there is one) was trained with
    ``run``'s configuration; where it trained (``device``) does not count."""
    from learn.checkpoint import check_inputs, load_checkpoint
    from learn.train import run_from_dict

    if not path.is_file():
        return
    ckpt = load_checkpoint(path)
    stored = run_from_dict(ckpt["config"])
    check_inputs(ckpt, stored.task, str(path))
    if dataclasses.replace(stored, device=run.device) != run:
        raise ConfigError(
            f"{path} was trained with another configuration than this experiment asks for "
            f"(stored {stored.model.arch} {stored.train}, asked {run.model.arch} {run.train}). "
            "Fix: give another --models folder, or delete that folder to retrain"
        )
