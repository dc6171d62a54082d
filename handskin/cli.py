"""The `handskin` console command: one typer app; each package adds its subcommands."""

from __future__ import annotations

import errno
import functools
from typing import Annotated

import typer

from experiments.cli import register as register_experiments
from handskin import __version__
from learn.cli import register as register_learn
from sim.cli.parts import register as register_sim
from sim.cli.view import register as register_view
from tactile.cli.dataset import register as register_dataset
from tactile.cli.map import register as register_tactile
from tactile.cli.stats import register as register_stats
from tactile.errors import HandskinError
from tactile.files import os_error_text

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
    register_stats,
    register_view,
    register_learn,
    register_experiments,
):
    register(app)


def guarded(callback):
    """``callback`` whose uncaught user errors (HandskinError) and system errors (OSError: full
    disk, read-only disk, damaged file) print one ``error:`` line and exit 2, no traceback."""

    @functools.wraps(callback)
    def run(*args, **kwargs):
        try:
            return callback(*args, **kwargs)
        except HandskinError as err:
            typer.echo(f"error: {err}", err=True)
            raise typer.Exit(2) from err
        except OSError as err:
            if err.errno == errno.EPIPE:  # stdout closed (`| head`): click ends quietly
                raise
            typer.echo(f"error: {os_error_text(err)}", err=True)
            raise typer.Exit(2) from err

    return run


def _guard_all(typer_app: typer.Typer) -> None:
    for info in typer_app.registered_commands:
        info.callback = guarded(info.callback)
    for group in typer_app.registered_groups:
        _guard_all(group.typer_instance)


_guard_all(app)


def main() -> None:
    """Entry point of the console script."""
    app()
