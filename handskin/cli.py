"""The `handskin` console command: one typer app; each package adds its subcommands."""

from __future__ import annotations

from typing import Annotated

import typer

from experiments.cli import register as register_experiments
from handskin import __version__
from learn.cli import register as register_learn
from sim.cli import register as register_sim
from sim.view_cli import register as register_view
from tactile.cli import register as register_tactile
from tactile.dataset.cli import register as register_dataset

app = typer.Typer(
    name="handskin",
    help="Simulation-backed labelled tactile data for robot skin: maps, images, datasets, models.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"handskin {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[
        bool,
        typer.Option("--version", callback=_version, is_eager=True, help="Print the version."),
    ] = False,
) -> None:
    """handskin: tactile maps, synthetic tactile datasets and touch-recognition models."""


for register in (
    register_tactile,
    register_sim,
    register_dataset,
    register_view,
    register_learn,
    register_experiments,
):
    register(app)


def main() -> None:
    """Entry point of the console script."""
    app()
