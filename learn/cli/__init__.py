"""`handskin train`, `finetune`, `evaluate`, `predict`, `stream` and `quantize`
(``register(app)`` adds them).

Every input is checked (files exist, configuration valid, architecture known) before any work;
errors print ``error: <what and how to fix>`` and exit with status 2. The modules that need
torch are imported inside the commands: PyTorch is an optional extra (and `handskin --help`
stays fast without it).
"""

from __future__ import annotations

import typer

from learn.cli.evaluate import evaluate_command, quantize_command
from learn.cli.finetune import finetune_command
from learn.cli.infer import predict_command, stream_command
from learn.cli.options import needs_torch
from learn.cli.train import train_command


def register(app: typer.Typer) -> None:
    """Add `train`, `finetune`, `evaluate`, `predict`, `stream` and `quantize` to the app."""
    for name, command in (
        ("train", train_command),
        ("finetune", finetune_command),
        ("evaluate", evaluate_command),
        ("predict", predict_command),
        ("stream", stream_command),
        ("quantize", quantize_command),
    ):
        app.command(name)(needs_torch(command))
