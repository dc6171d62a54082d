"""Models trained once and reused: a run folder that holds a finished run of the same
configuration is taken as it is, a stopped one resumed, an empty one trained.

    ckpt = ensure_model("handsnet", "out/forearm", out / "models", epochs=8)   # -> Path to .pt

The segmenters' encoder start and the experiments share their models this way: a model trained
into ``models_dir/<arch>`` is reused (and said so) by a later call with the same folder.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from pathlib import Path

from learn.config import preset_run
from learn.data.load import load_data
from learn.train.checkpoint import BEST, LAST, check_inputs, load_checkpoint, run_of
from learn.train.loop import fit
from learn.train.state import check_same_data, patience_out
from tactile.errors import ConfigError, DataError


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
    run : a ``learn.config.RunConfig`` to train with (default: the arch's preset on ``device``,
    with ``epochs`` and ``seed`` changed when given). The model is trained into
    ``models_dir/<name or arch>`` and reused when ``best.pt`` is already there, wherever it
    trained.
    """
    if checkpoint is not None:
        checkpoint = Path(checkpoint)
        if not checkpoint.is_file():
            raise DataError(f"no checkpoint at {checkpoint}. Fix: a .pt file from handskin train")
        return checkpoint
    out = Path(models_dir) / (name or arch)
    run = run if run is not None else preset_run(arch, epochs=epochs, seed=seed, device=device)
    if run.model.arch != arch:
        run = dataclasses.replace(run, model=dataclasses.replace(run.model, arch=arch))
    return train_once(
        out,
        run,
        lambda: load_data(data, run, with_test=False, progress=progress),
        progress=progress,
        data=data,
    )[0]


def finished(out_dir: str | Path, run) -> bool:
    """True when ``out_dir/last.pt`` ends ``run``: its schedule's last epoch is done, or
    patience stopped it; False for a stopped (paused or killed) run, and without last.pt."""
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
    init: str | Path | None = None,
    progress: bool = True,
    data: str | Path | None = None,
) -> tuple[Path, bool]:
    """(``out/best.pt``, whether this call trained) for ``run`` trained into ``out``.

    A finished run there is reused (and said so); a stopped one (killed, or paused mid-schedule)
    resumes from its ``last.pt``, so a long experiment interrupted mid-training neither restarts
    that model nor takes its half-trained weights as done; else ``make_data()`` is trained on.
    ConfigError, before any work, when ``out`` holds a run of another configuration, or of the
    dataset at ``data`` (its path) before it was regenerated with other settings.
    """
    last, best = out / LAST, out / BEST
    check_reusable(last if last.is_file() else best, run, data)
    if best.is_file() and (not last.is_file() or finished(out, run)):
        print(f"reusing {best}")
        return best, False
    if last.is_file():
        print(f"resuming the stopped run in {out}")
    fit(run, make_data(), out, resume=True, init=init, progress=progress)
    return best, True


def check_reusable(path: Path, run, data: str | Path | None = None) -> None:
    """ConfigError unless the checkpoint at ``path`` (when there is one) was trained with
    ``run``'s configuration (where it trained, ``device``, does not count) and, given its path,
    on the dataset at ``data`` as it is now (`learn.train.state.check_same_data`)."""
    if not path.is_file():
        return
    ckpt = load_checkpoint(path)
    stored = run_of(ckpt, path)
    check_inputs(ckpt, stored.task, str(path))
    if dataclasses.replace(stored, device=run.device) != run:
        raise ConfigError(
            f"{path} was trained with another configuration than this experiment asks for "
            f"(stored {stored.model.arch} {stored.train}, asked {run.model.arch} {run.train}). "
            "Fix: give another --models folder, or delete that folder to retrain"
        )
    check_same_data(ckpt, data, str(path))
