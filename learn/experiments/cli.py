"""`handskin experiment <name>`: one sub-app; each experiment module adds its command.

Every experiment module exposes ``register(app: typer.Typer) -> None``; list it in ``MODULES``.
Imports stay lazy so `handskin --help` needs no torch.
"""

from __future__ import annotations

import importlib

import typer

#: Modules (import paths) whose ``register(app)`` adds an experiment command.
MODULES: tuple[str, ...] = (
    "learn.experiments.robustness",
    "learn.experiments.fault_aware",
    "learn.experiments.pareto",
)

app = typer.Typer(
    name="experiment",
    help="Experiments: robustness-a|b, transfer, fault-aware, pareto, fidelity. Each writes a "
    "folder with report.md, results.json and PNG charts; --quick runs a small version.",
    no_args_is_help=True,
)


def register(root: typer.Typer, extra_modules: tuple[str, ...] = ()) -> None:
    """Add `handskin experiment ...` to the root app (``extra_modules``: outside learn/)."""
    for name in (*MODULES, *extra_modules):
        importlib.import_module(name).register(app)
    root.add_typer(app, name="experiment")
