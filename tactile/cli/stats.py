"""`handskin stats`: a dataset's prints (or two side by side) against measurements of real hands."""

from __future__ import annotations

import shlex
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from tactile.dataset.boxes import (
    CONTACT_LEVEL,
    PAPER_PIXEL_MM,
    BoxFolder,
    box_labels,
    is_box_folder,
    parse_frame,
)
from tactile.dataset.reader import open_dataset
from tactile.errors import ConfigError, DataError, HandskinError
from tactile.files import require_output, write_text_atomic
from tactile.images.labels import IGNORE
from tactile.prints.shapes import (
    CHIRALITY,
    EXTENT,
    LAYOUT,
    MIN_BLOB_PX,
    STATISTICS,
    WITHOUT_PALM,
    Shapes,
    chirality,
    dataset_shapes,
    folder_shapes,
    quartiles,
    shapes_markdown,
    without_palm,
)
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


def check_outputs(out: Path | None, png: Path | None, reads: list[Path] = ()) -> None:
    """ConfigError before any work: ``--out`` (.md) and ``--png`` (.png) that cannot be written or
    would write over a file the command ``reads`` (`tactile.files.require_output`)."""
    require_output(out, "--out", reads=reads, suffixes=(".md",))
    require_output(png, "--png", reads=reads, suffixes=(".png",))


def names_of(paths: list[Path]) -> list[str]:
    """Short names of the datasets (their folder names; made distinct when they coincide)."""
    names = [(p.parent if p.name == "dataset.h5" else p).name or str(p) for p in paths]
    if len(names) == 2 and names[0] == names[1]:
        names = [f"{names[0]} (1)", f"{names[1]} (2)"]
    return names


def stats_command(
    dataset: Annotated[
        Path,
        typer.Argument(
            metavar="DATASET",
            help="Dataset folder (or its dataset.h5), or a folder of box-labelled real prints.",
        ),
    ],
    dataset2: Annotated[
        Path | None,
        typer.Argument(metavar="DATASET2", help="A second one, shown beside the first."),
    ] = None,
    out: Annotated[
        Path | None, typer.Option(help="Markdown report to write (.md): every table.")
    ] = None,
    png: Annotated[
        Path | None,
        typer.Option(help="PNG of the distributions, part shares and anchored figures."),
    ] = None,
    seed: Annotated[int, typer.Option(help="Seed of the bootstrap (integer >= 0).")] = 0,
    classes: Annotated[
        str | None,
        typer.Option(
            help="Box folders: the label files' class names in order, comma-separated "
            "(default: the folder's data.yaml), e.g. palm,thumb,index,middle,ring,pinkie."
        ),
    ] = None,
    frame: Annotated[
        str | None,
        typer.Option(
            help="Box folders: the images' native frame, ROWSxCOLUMNS px, that each "
            "stretched image is resized back to, e.g. 247x362 (default: as stored)."
        ),
    ] = None,
    box_step_mm: Annotated[
        float,
        typer.Option(help="Box folders: mm of skin a pixel (the paper's images, docs/stats.md)."),
    ] = PAPER_PIXEL_MM,
    level: Annotated[
        int, typer.Option(help="Print shapes: contact is a grey level above this (0..254).")
    ] = CONTACT_LEVEL,
    min_blob_px: Annotated[
        int, typer.Option(help="Print shapes: blobs of fewer pixels are specks (>= 1).")
    ] = MIN_BLOB_PX,
    sheet: Annotated[
        Path | None,
        typer.Option(
            help="Box folders: a PNG contact sheet of each input's hand prints side by side, "
            "their parts coloured (box-derived for a box folder)."
        ),
    ] = None,
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
    generated datasets and ingested recordings; two are laid side by side.

    A folder of real box-labelled prints (the real_hands layout) is described by six statistics
    of the print's shape (blobs, area mm², span mm, parts boxed, fingers with a blob of their
    own, the palm's share), where the parts lie and which way the hand is drawn; a dataset
    beside it is measured alike on its hand prints (each part boxed tightly), by action too.
    """
    paths = [dataset] if dataset2 is None else [dataset, dataset2]
    try:
        if seed < 0:
            raise ConfigError(f"--seed {seed} is out of range; allowed >= 0")
        if any(is_box_folder(p) for p in paths):
            shape_report(paths, out, png, classes, frame, level, min_blob_px, sheet, box_step_mm)
            return
        if sheet is not None:
            raise ConfigError(
                "--sheet lays hand prints beside real box-labelled ones. Fix: give a box folder "
                "(handskin ingest-boxes) as DATASET or DATASET2, or leave --sheet out"
            )
        for path, what in zip(paths, ("DATASET", "DATASET2"), strict=False):
            check_dataset(path, what)
        check_outputs(out, png, paths)
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


def shape_report(
    paths, out, png, classes, frame, level, min_blob_px, sheet=None, box_step_mm=PAPER_PIXEL_MM
) -> None:
    """`handskin stats` with a box folder among its inputs: the six print statistics of each
    input side by side, against the first box folder's interquartile range; with ``sheet``, a
    contact sheet of each input's hand prints."""
    if not 0 <= level <= 254:
        raise ConfigError(f"--level {level} is out of range; allowed 0..254")
    if min_blob_px < 1:
        raise ConfigError(f"--min-blob-px {min_blob_px} is out of range; allowed >= 1")
    if not 0.05 <= box_step_mm <= 20:
        raise ConfigError(f"--box-step-mm {box_step_mm} is out of range; allowed 0.05..20 mm")
    names = [c.strip() for c in classes.split(",")] if classes else None
    frame_px = parse_frame(frame)
    folders = {}
    for path, what in zip(paths, ("DATASET", "DATASET2"), strict=False):
        if is_box_folder(path):
            folders[path] = BoxFolder.open(path, names, frame_px)
        else:
            check_dataset(path, what)
    check_outputs(out, png, paths)
    require_output(sheet, "--sheet", reads=paths, suffixes=(".png",))
    tiles = []  # the sheet's prints, read before any statistic is written
    if sheet is not None:
        for path, name in zip(paths, names_of(paths), strict=True):
            tiles += hand_tiles(path, name, folders, level)
    sets: dict[str, Shapes] = {}
    for path, name in zip(paths, names_of(paths), strict=True):
        if path in folders:
            sets[name] = folder_shapes(folders[path], level, min_blob_px, box_step_mm)
            continue
        with open_dataset(path) as ds:
            if "label_image" not in ds.fields:
                raise DataError(f"{path} has no label_image: its hand parts are unknown")
            sets[name] = dataset_shapes(ds, level, min_blob_px)
    reference = next(n for p, n in zip(paths, sets, strict=True) if p in folders)
    if out is not None:
        words = command_words(paths, out, png, 0)
        for flag, value, default in (
            ("--classes", classes, None),
            ("--frame", frame, None),
            ("--level", level, CONTACT_LEVEL),
            ("--min-blob-px", min_blob_px, MIN_BLOB_PX),
            ("--box-step-mm", box_step_mm, PAPER_PIXEL_MM),
        ):
            words += [flag, str(value)] if value != default else []
        rule = (
            f"Contact: grey level above {level}, in 8-connected blobs of at least {min_blob_px} "
            f"px; a box folder's pixel read as {box_step_mm:g} mm of skin, a dataset's at its "
            "map's step. A simulated print's parts are boxed tightly around their contact "
            "pixels; labels inside boxes are box-derived (the smallest box holding a pixel)."
        )
        head = f"# Print shapes: {' and '.join(sets)}\n\nRegenerate: `{shlex.join(words)}`\n\n"
        write_text_atomic(out, f"{head}{rule}\n\n{shapes_markdown(sets, reference)}")
    if png is not None:
        from tactile.prints.plot import save_shapes_png  # start-up: matplotlib

        save_shapes_png(sets, png, reference)
    if sheet is not None:
        from tactile.figures.sheet import padded, save_contact_sheet  # start-up: matplotlib

        images, labels, titles = zip(*tiles, strict=True)
        save_contact_sheet(
            sheet,
            padded(images),
            labels=padded(labels),
            titles=list(titles),
            n_cols=SHEET_COLUMNS,
            title=f"hand prints: {' and '.join(sets)} (parts of a box folder box-derived)",
            tile_in=2.0,
        )
    layout = {k: (f"{label} (box centres), mm", "{:.0f}") for k, label in LAYOUT.items()}
    extent = {k: (f"extent {label}, mm", "{:.0f}") for k, label in EXTENT.items()}
    for key, (label, fmt) in (STATISTICS | extent | layout).items():
        cells = []
        for name, s in sets.items():
            q = quartiles(s.values[key])
            cells.append(f"{name} {'n/a' if q is None else fmt.format(q[1])}")
        typer.echo(f"{label}, median: " + "; ".join(cells))
    for key, label in CHIRALITY.items():
        typer.echo(
            f"{label}, share: "
            + "; ".join(f"{name} {chirality(s, key):.2f}" for name, s in sets.items())
        )
    typer.echo(
        f"{WITHOUT_PALM}, share: "
        + "; ".join(f"{name} {without_palm(s):.2f}" for name, s in sets.items())
    )
    for flag, path in (("report", out), ("picture", png), ("contact sheet", sheet)):
        if path is not None:
            typer.echo(f"{flag}: {path}")


SHEET_COLUMNS = 6  # tiles a row of `--sheet`
SHEET_PRINTS = 12  # hand prints of each input on `--sheet`, evenly spaced over its order


def spaced(n: int) -> np.ndarray:
    """Up to `SHEET_PRINTS` distinct indices evenly spaced over ``range(n)``, first and last
    included."""
    return np.unique(np.linspace(0, n - 1, SHEET_PRINTS).round().astype(int))


def hand_tiles(path: Path, name: str, folders: dict, level: int) -> list[tuple]:
    """(image, labels, title) of `SHEET_PRINTS` hand prints of one input, evenly spaced over its
    order: a box folder's prints with box-derived labels (contact in no box left grey), a
    dataset's hand samples with their label images."""
    if path in folders:
        folder = folders[path]
        picks = spaced(len(folder))
        tiles = []
        for i in picks:
            p = folder[int(i)]
            labels = box_labels(p.image, p.boxes, level)
            tiles.append((p.image, np.where(labels == IGNORE, 0, labels), f"{name} {p.name}"))
        return tiles
    with open_dataset(path) as ds:
        hands = np.flatnonzero(ds["is_hand"][:])
        if len(hands) == 0:
            raise DataError(f"{path} holds no hand print for --sheet")
        picks = hands[spaced(len(hands))]
        samples = [ds[int(i)] for i in picks]
        return [
            (s["image"], s["label_image"], f"{name} #{i}")
            for s, i in zip(samples, picks, strict=True)
        ]


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
