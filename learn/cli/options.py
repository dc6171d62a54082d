"""What the commands of learn/ (and the experiments) share: the error exit, option types, the
check that PyTorch is installed, the dataset argument's check."""

from __future__ import annotations

import functools
import importlib.util
import warnings
from pathlib import Path
from typing import Annotated

import typer

from tactile.dataset.folder import DATASET
from tactile.errors import DataError


def fail(err: Exception) -> typer.Exit:
    """Print ``error: ...`` for a user error and return the exit (status 2) to raise."""
    typer.echo(f"error: {err.args[0] if isinstance(err, KeyError) else err}", err=True)
    return typer.Exit(2)


def opt(kind, help_text: str, *names: str):
    """``Annotated[kind, typer.Option(*names, help=help_text)]``."""
    return Annotated[kind, typer.Option(*names, help=help_text)]


# options shared by the commands of learn/ and the experiments
DataArg = Annotated[
    Path, typer.Argument(metavar="DATASET", help="Dataset folder (dataset.h5) or image folder.")
]
SeedOpt = opt(int | None, "Seed of init, shuffling and splits (integer).")
ThreadsOpt = opt(int, "CPU threads (count).")
DeviceOpt = opt(
    str | None, "Where networks train: cpu (reproducible from the seed), cuda or cuda:N."
)
ProgressOpt = opt(bool, "Show progress bars.", "--progress/--no-progress")
HandOpt = opt(
    str | None, "Image folders: comma-separated folder names that are 'hand'.", "--hand-classes"
)
ClfOpt = Annotated[
    list[Path] | None,
    typer.Option(
        metavar="PATH",
        help="Classifier (.pt), or a class-and-parts network (handparts: it answers both); "
        "given twice or more: their mean softmax.",
    ),
]
SegOpt = Annotated[
    list[Path] | None,
    typer.Option(metavar="PATH", help="Segmenter (.pt); given twice or more: their mean softmax."),
]
TtaOpt = opt(bool, "Test-time flips: each network's mean softmax over its training views.", "--tta")


def hand_classes(text: str | None) -> tuple[str, ...] | None:
    """``--hand-classes`` as a tuple of folder names (None when not given)."""
    return None if not text else tuple(t.strip() for t in text.split(",") if t.strip())


def needs_torch(command):
    """``command`` preceded by a clear error when PyTorch is not installed (it is an extra)."""

    @functools.wraps(command)
    def checked(*args, **kwargs):
        if importlib.util.find_spec("torch") is None:
            typer.echo(
                "error: this command needs PyTorch, which handskin installs with its 'learn' "
                "extra. Fix: pip install 'handskin[learn]' (without a GPU, install the CPU "
                "wheel of torch first)",
                err=True,
            )
            raise typer.Exit(2)
        with warnings.catch_warnings():  # a warning is one line for the user, not a source line
            warnings.showwarning = lambda message, *_: typer.echo(f"warning: {message}", err=True)
            return command(*args, **kwargs)

    return checked


def check_data(data: Path) -> None:
    """A dataset folder, a dataset.h5 or an image folder at ``data``; DataError otherwise."""
    if not (data.is_dir() or (data.is_file() and data.suffix == ".h5")):
        raise DataError(
            f"no dataset or image folder at {data}. Fix: a dataset folder (holding dataset.h5) "
            "or a folder of class sub-folders of images"
        )


def is_dataset_path(data: Path) -> bool:
    """A handskin dataset folder (or its dataset.h5), not an image folder."""
    return (data / DATASET).is_file() or (data.is_file() and data.suffix == ".h5")
