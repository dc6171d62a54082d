"""`handskin stats`: a dataset's prints (or two side by side) against measurements of real hands."""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Annotated

import typer

from tactile.dataset.reader import open_dataset
from tactile.errors import ConfigError, DataError, HandskinError
from tactile.files import require_writable, write_text_atomic
from tactile.prints.stats import dataset_stats, stats_markdown, summary_lines

NEEDED = ("pressure_pa", "image")  # fields every statistic needs (raw is always there)


def check_dataset(path: Path, what: str) -> int:
    """The sample count of the dataset at ``path``; DataError naming ``what`` (the argument) when
    it is not a dataset, holds no samples or lacks the fields the statistics need."""
    try:
        with open_dataset(path) as ds:
            missing = [f for f in NEEDED if f not in ds.fields]
            n = len(ds)
    except DataError as err:
        raise DataError(f"{what} {path}: {err}") from err
    if missing:
        raise DataError(
            f"{what} {path} has no {', '.join(missing)} field. Fix: give a dataset made by "
            "`handskin generate` or `handskin ingest`"
        )
    if not n:
        raise DataError(f"{what} {path} holds no samples. Fix: give a dataset with samples")
    return n


def check_outputs(out: Path | None, png: Path | None) -> None:
    """ConfigError before any work: an unwritable ``--out``/``--png``, or ``--png`` not .png."""
    if out is not None:
        require_writable(out, "--out")
    if png is not None:
        if png.suffix.lower() != ".png":
            raise ConfigError(f"--png {png}: not a .png file. Fix: e.g. --png {png.stem}.png")
        require_writable(png, "--png")


def names_of(paths: list[Path]) -> list[str]:
    """Short names of the datasets (their folder names; made distinct when they coincide)."""
    names = [(p.parent if p.name == "dataset.h5" else p).name or str(p) for p in paths]
    if len(names) == 2 and names[0] == names[1]:
        names = [f"{names[0]} (1)", f"{names[1]} (2)"]
    return names


def stats_command(
    dataset: Annotated[
        Path,
        typer.Argument(metavar="DATASET", help="Dataset folder (or its dataset.h5)."),
    ],
    dataset2: Annotated[
        Path | None,
        typer.Argument(metavar="DATASET2", help="A second dataset, shown beside the first."),
    ] = None,
    out: Annotated[
        Path | None, typer.Option(help="Markdown report to write (.md): every table.")
    ] = None,
    png: Annotated[
        Path | None,
        typer.Option(help="PNG of the distributions, part shares and anchored figures."),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the bootstrap (integer >= 0).")] = 0,
    progress: Annotated[
        bool, typer.Option("--progress/--no-progress", help="Show a progress bar.")
    ] = True,
) -> None:
    """Statistics of a set of prints beside published measurements of real hands.

    Active taxels, contact area (mm²), separate blobs before and after the image morphology,
    parts per hand, each part's share of pixels and of pressure (%), press force (N), by
    contactor kind and action, with 95 % bootstrap intervals over samples; the published range
    beside each figure that has one (the seed paper's people and Fig. 10; finger force sharing
    in grip, Li 2002 and J Hand Surg 2014) and whether the figure lies inside it. Works on
    generated datasets and ingested recordings (a figure the dataset cannot give reads "not in
    this dataset"); two datasets are laid side by side.
    """
    paths = [dataset] if dataset2 is None else [dataset, dataset2]
    try:
        if seed < 0:
            raise ConfigError(f"--seed {seed} is out of range; allowed >= 0")
        for path, what in zip(paths, ("DATASET", "DATASET2"), strict=False):
            check_dataset(path, what)
        check_outputs(out, png)
        stats = [
            dataset_stats(p, name=n, seed=seed, progress=progress)
            for p, n in zip(paths, names_of(paths), strict=True)
        ]
        if out is not None:
            title, rest = stats_markdown(stats, seed).split("\n", 1)
            command = f"Regenerate: `{shlex.join(command_words(paths, out, png, seed))}`"
            write_text_atomic(out, f"{title}\n\n{command}\n{rest}")
        if png is not None:
            from tactile.prints.plot import save_stats_png  # start-up: matplotlib

            save_stats_png(stats, png)
    except HandskinError as err:
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(2) from err
    for line in summary_lines(stats):
        typer.echo(line)
    for flag, path in (("report", out), ("picture", png)):
        if path is not None:
            typer.echo(f"{flag}: {path}")


def command_words(paths: list[Path], out: Path | None, png: Path | None, seed: int) -> list[str]:
    """The `handskin stats` command that writes this report (its first line)."""
    words = ["handskin", "stats", *map(str, paths)]
    for flag, value in (("--out", out), ("--png", png), ("--seed", seed or None)):
        words += [flag, str(value)] if value is not None else []
    return words


def register(app: typer.Typer) -> None:
    """Add `stats` to the `handskin` app (its help: the docstring's paragraphs, unwrapped)."""
    paragraphs = (stats_command.__doc__ or "").split("\n\n")
    app.command("stats", help="\n\n".join(" ".join(p.split()) for p in paragraphs))(stats_command)
