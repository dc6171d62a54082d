"""`handskin map`: build a tactile map from a layout file, report it and picture it."""

from __future__ import annotations

import dataclasses
import warnings
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from tactile.errors import ConfigError, HandskinError, require_positive
from tactile.files import atomic_path, require_output, writing
from tactile.geometry.layout import TaxelLayout
from tactile.geometry.synthetic import cylinder_sector_layout
from tactile.images.tactile_map import TactileMap


def describe_map(tmap) -> str:
    """A short text report: counts, image size, distortion summary."""
    s = tmap.distortion.summary()
    h, w = tmap.shape
    n_unplaced = int(np.sum(~np.isfinite(tmap.uv[:, 0])))
    lines = [
        f"taxels      {tmap.n_taxels} ({tmap.n_taxels - n_unplaced} placed, {n_unplaced} unplaced)",
        f"triangles   {len(tmap.triangles)}",
        f"image       {h} rows × {w} columns at {tmap.step_mm:g} mm/px"
        f" ({h * tmap.step_mm:.0f} × {w * tmap.step_mm:.0f} mm)",
    ]
    lines += [f"{k:<26}{v:.4g}" for k, v in s.items()]
    return "\n".join(lines)


def map_command(
    layout: Annotated[
        Path | None,
        typer.Argument(
            metavar="LAYOUT",
            help="Taxel layout file: .npz, .csv or iCub .txt. Default: the built-in forearm-like "
            "layout (a hex lattice of 11 mm pitch on a 75 mm-radius sector, 247 × 362 mm).",
        ),
    ] = None,
    png: Annotated[
        Path | None, typer.Option(help="Write a picture of the flat map (PNG) to this file.")
    ] = None,
    step_mm: Annotated[float, typer.Option(help="Grid step of the tactile image, mm/pixel.")] = 1.0,
    units: Annotated[
        str | None,
        typer.Option(help="Units of positions in a plain file without unit columns: 'm' or 'mm'."),
    ] = None,
    out: Annotated[
        Path | None,
        typer.Option(help="Save the map (.npz: flat mesh and grid; TactileMap.load reads it)."),
    ] = None,
) -> None:
    """Build the tactile map of a taxel layout; print counts, image size and distortion."""
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            require_positive("--step-mm", step_mm, "mm/pixel")
            if units not in (None, "m", "mm"):
                raise ConfigError(f"--units {units!r} unknown; choose m or mm")
            require_output(out, "--out", reads=[layout], suffixes=(".npz",))
            require_output(png, "--png", reads=[layout], suffixes=(".png",))
            lay = _load_layout(layout, units)
            tmap = TactileMap.build(lay, step_mm=step_mm)
    except HandskinError as err:
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(2) from err
    for w in caught:
        typer.echo(f"warning: {w.message}", err=True)
    typer.echo(describe_map(tmap))
    try:
        if out is not None:
            with writing(out), atomic_path(out, keep_suffix=True) as tmp:
                tmap.save(tmp)
            typer.echo(f"map saved to {out}")
        if png is not None:
            from tactile.figures.maps import save_map_picture  # start-up: matplotlib

            with writing(png):
                save_map_picture(tmap, png, title=lay.name)
            typer.echo(f"picture written to {png}")
    except HandskinError as err:
        typer.echo(f"error: {err}", err=True)
        raise typer.Exit(2) from err


def _load_layout(path: Path | None, units: str | None):
    """The layout in ``path``, or the built-in forearm-like layout when no path is given."""
    if path is None:
        return cylinder_sector_layout(name="forearm-like lattice (built-in)")[0]
    lay = TaxelLayout.load(path, units=units)
    return lay if lay.name else dataclasses.replace(lay, name=path.stem)


def register(app: typer.Typer) -> None:
    """Add the tactile subcommands to the `handskin` app."""
    app.command("map")(map_command)
