"""`handskin export` and `handskin ingest`: PNG folders from a dataset, datasets from recordings."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from tactile.errors import HandskinError


def _fail(err: Exception) -> None:
    typer.echo(f"error: {err}", err=True)
    raise typer.Exit(2) from err


def export_command(
    dataset_dir: Annotated[
        Path, typer.Argument(help="Dataset folder (holding dataset.h5) or the dataset.h5 file.")
    ],
    png: Annotated[
        Path,
        typer.Option(
            help="Output folder for PNG images (8-bit grey tactile images, 1 pixel = step_mm "
            "of the map, in hand/, non_hand/; RGB label images in labels/)."
        ),
    ],
) -> None:
    """Export a dataset's tactile images and label images as PNG files."""
    from tactile.dataset.export import export_png

    try:
        written = export_png(dataset_dir, png)
    except HandskinError as err:
        _fail(err)
    for folder, n in sorted(written.items()):
        typer.echo(f"{folder:<11}{n} PNG files")
    typer.echo(f"written to {png}")


def ingest_command(
    layout: Annotated[
        Path, typer.Argument(help="Taxel layout file: iCub .txt, .csv (positions in m) or .npz.")
    ],
    frames: Annotated[
        Path,
        typer.Argument(
            help="Frames, .csv or .npy, one frame per row, raw 16-bit counts: C = n_channels "
            "columns (raw channel frames) or N = n_taxels columns (taxel frames)."
        ),
    ],
    out: Annotated[
        Path, typer.Option(help="Output dataset folder (new or empty; a folder path).")
    ],
    labels: Annotated[
        Path | None,
        typer.Option(help="Per-frame class labels (.csv/.npy, one per frame, unitless): "
                     "1 or hand, 0 or non_hand."),
    ] = None,
    part_labels: Annotated[
        Path | None,
        typer.Option(help="Per-taxel part labels (.csv/.npy, T rows x N columns, unitless "
                     "class ids 0..6 of tactile.CLASS_NAMES)."),
    ] = None,
    baseline: Annotated[
        Path | None,
        typer.Option(help="Untouched frames (.csv/.npy, raw counts, same columns as FRAMES); "
                     "their mean per taxel is subtracted. Default: 0 counts."),
    ] = None,
    step_mm: Annotated[float, typer.Option(help="Grid step of the tactile image, mm/pixel.")] = 1.0,
    counts_per_pa: Annotated[
        float,
        typer.Option(help="Skin gain, counts/Pa; 1.0 leaves pressures in counts (uncalibrated)."),
    ] = 1.0,
) -> None:
    """Turn a real skin recording (layout + frames) into a handskin dataset folder."""
    from tactile.dataset.ingest import ingest_recording

    try:
        path = ingest_recording(
            layout, frames, out, labels_path=labels, part_labels_path=part_labels,
            baseline_path=baseline, step_mm=step_mm, counts_per_pa=counts_per_pa,
        )  # fmt: skip
    except HandskinError as err:
        _fail(err)
    typer.echo(f"dataset written to {path}")


def register(app: typer.Typer) -> None:
    """Add `export` and `ingest` to the `handskin` app."""
    app.command("export")(export_command)
    app.command("ingest")(ingest_command)
