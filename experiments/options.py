"""Command-line options and input checks shared by the experiments (torch-free).

``learn.cli.options`` gives the options every command of handskin shares (``--seed``, ``--device``,
``--progress``); these are the experiments' own. Checks raise before any work, naming the flag.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from learn.cli.options import DeviceOpt, ProgressOpt, SeedOpt, opt
from tactile.errors import ConfigError, DataError, require_folder
from tactile.files import require_output

__all__ = ["DeviceOpt", "ProgressOpt", "SeedOpt", "opt"]

DatasetArg = Annotated[
    Path, typer.Argument(metavar="DATASET", help="Dataset folder (holding dataset.h5).")
]
OutOpt = opt(Path, "Report folder: report.md, results.json, PNG charts.", "--out")
QuickOpt = opt(bool, "A small version, minutes (sizes above).", "--quick")
ModelsOpt = opt(Path | None, "Trained networks, reused (OUT/models).")
ClassifierOpt = opt(Path | None, "Classifier (.pt); default: trained here.")
SegmenterOpt = opt(Path | None, "Segmenter (.pt); default: trained here.")
SegmentationOpt = opt(bool, "Also the segmenter (SegNet).", "--segmentation/--no-segmentation")
ThreadsOpt = opt(int, "CPU threads of torch (count).")
DatasetsOpt = opt(Path | None, "Generated datasets, reused (OUT/data).")


def check_dataset(path: Path, what: str = "DATASET") -> Path:
    """``path`` when it is a dataset folder; DataError naming ``what`` and the fix."""
    if not (Path(path) / "dataset.h5").is_file():
        raise DataError(
            f"{what} {path}: no dataset there. Fix: a folder holding dataset.h5 (handskin "
            "generate or handskin ingest writes one)"
        )
    return Path(path)


def check_at_least(flag: str, value: int | None, least: int = 1) -> None:
    """ConfigError naming ``flag`` when ``value`` (None: not given) is below ``least``."""
    if value is not None and value < least:
        raise ConfigError(f"{flag} {value} is out of range; allowed >= {least}")


def check_out(
    out: Path, *others: tuple[str, Path | None], reads: tuple[Path | None, ...] = ()
) -> None:
    """The report folder and other output folders (flag, path) can be created and written, and
    are neither a folder the experiment ``reads`` nor a dataset or run folder
    (`tactile.files.require_output`)."""
    for flag, path in (("--out", out), *others):
        if path is not None:
            require_folder(Path(path), flag)
            require_output(Path(path), flag, reads=reads, folder=True)


def parse_list(flag: str, text: str | None, kind: type, skip: tuple[str, ...] = ()) -> tuple | None:
    """``--flag a,b,c`` as a tuple of ``kind`` (None when not given; ``skip``: words left out)."""
    if text is None:
        return None
    try:
        return tuple(kind(t.strip()) for t in text.split(",") if t.strip() not in ("", *skip))
    except ValueError:
        raise ConfigError(f"{flag} {text!r}: give comma-separated values, e.g. 10,30,100") from None


def check_segmenter(segmentation: bool, segmenter: Path | None) -> None:
    """ConfigError when a segmenter is given with ``--no-segmentation``."""
    if segmenter is not None and not segmentation:
        raise ConfigError(
            "--segmenter with --no-segmentation: nothing would use it. Fix: drop one of them"
        )
