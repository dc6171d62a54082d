"""The `handskin` console command: one typer app whose subcommands live beside their packages."""

from __future__ import annotations

from typing import Annotated

import typer

from handskin import __version__

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


def _register() -> None:
    from learn.cli import register as register_learn
    from learn.experiments.cli import register as register_experiments
    from sim.cli import register as register_sim
    from sim.view_cli import register as register_view
    from tactile.cli import register as register_tactile
    from tactile.dataset.cli import register as register_dataset

    register_tactile(app)
    register_sim(app)
    register_dataset(app)
    register_view(app)
    register_learn(app)
    register_experiments(app, extra_modules=("handskin.transfer", "handskin.fidelity"))


_register()


def main() -> None:
    """Entry point of the console script."""
    app()
