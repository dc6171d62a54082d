"""The `handskin experiment` sub-app: one command per registered experiment."""

from __future__ import annotations

import typer

from experiments import (
    EXPERIMENTS,
    candidates,
    fault_aware,
    fidelity,
    pareto,
    real_finetune,
    robustness,
    transfer,
)

#: the experiment modules; importing one registers its commands (`experiments.experiment`)
MODULES = (robustness, fault_aware, transfer, pareto, fidelity, real_finetune, candidates)


def register(root: typer.Typer) -> None:
    """Add `handskin experiment <name>` for every experiment to the root app."""
    app = typer.Typer(
        name="experiment",
        help="Experiments: robustness-a, robustness-b, fault-aware, transfer, pareto, fidelity, "
        "real-finetune, candidates. "
        "Each writes a folder with report.md, results.json and PNG charts.",
        no_args_is_help=True,
    )
    for name, command in EXPERIMENTS.items():
        app.command(name)(command)
    root.add_typer(app, name="experiment")
