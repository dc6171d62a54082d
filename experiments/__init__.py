"""`handskin experiment NAME`: studies built on learn/ and sim/, one command each.

Every experiment writes one folder: ``report.md`` (its tables beside the paper's numbers, with
the command, seed, configuration and package versions), ``results.json`` and PNG charts;
``--quick`` runs a small version in minutes. An experiment is one function registered here, as
dm_control registers its suite's tasks:

    @experiment("robustness-a")
    def robustness_a(dataset: DatasetArg, out: OutOpt, ...) -> Path:   # returns report.md

and `experiments.cli` adds every registered command to `handskin experiment`.
"""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path

import typer

from learn.cli.options import fail, needs_torch
from tactile.errors import HandskinError

#: name -> typer command of every registered experiment
EXPERIMENTS: dict[str, Callable[..., None]] = {}


def experiment(name: str) -> Callable[[Callable[..., Path]], Callable[..., None]]:
    """Register the decorated function as the command `handskin experiment NAME`.

    The function returns the path of the report it wrote. A user error (``HandskinError``)
    prints ``error: <what and how to fix>`` and exits with status 2; without PyTorch the
    command stops with the install hint (``learn.cli.options.needs_torch``).
    """

    def register(command: Callable[..., Path]) -> Callable[..., None]:
        if name in EXPERIMENTS:
            raise ValueError(f"experiment {name!r} is registered twice")

        @functools.wraps(command)
        def run(*args, **kwargs) -> None:
            try:
                path = command(*args, **kwargs)
            except (HandskinError, KeyError) as err:
                raise fail(err) from err
            typer.echo(f"report written to {path}")

        EXPERIMENTS[name] = needs_torch(run)
        return EXPERIMENTS[name]

    return register
