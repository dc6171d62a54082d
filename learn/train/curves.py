"""Training curves: loss (train, validation) and the validation metric per epoch, as a figure
or a PNG beside a run's checkpoints (``curves.png``)."""

from __future__ import annotations

import math
from pathlib import Path

from matplotlib.figure import Figure

from tactile.files import save_figure


def history_figure(
    history: list[dict],
    title: str = "",
    metric: str = "validation metric",
    best_epoch: int | None = None,
) -> Figure:
    """Loss curves (train, val) and the validation metric per epoch; ``best_epoch`` (1-based,
    the epoch ``best.pt`` holds) is marked on the metric's curve."""
    fig = Figure(figsize=(9, 3.5), layout="constrained")
    ax_loss, ax_metric = fig.subplots(1, 2)
    epochs = [h["epoch"] for h in history]
    ax_loss.plot(epochs, [h["train_loss"] for h in history], "o-", label="train")
    if any("val_loss" in h for h in history):
        values = [h.get("val_metric", math.nan) for h in history]
        ax_loss.plot(epochs, [h.get("val_loss", math.nan) for h in history], "s-", label="val")
        ax_metric.plot(epochs, values, "s-", c="C1")
        if best_epoch in epochs:
            value = values[epochs.index(best_epoch)]
            ax_metric.plot(
                [best_epoch],
                [value],
                "*",
                c="C3",
                ms=14,
                label=f"best.pt (epoch {best_epoch}, {value:.4f})",
            )
            ax_metric.legend(loc="lower right")
    ax_loss.set(xlabel="epoch", ylabel="loss", title="loss")
    ax_loss.legend()
    ax_metric.set(xlabel="epoch", ylabel="fraction", title=f"validation {metric}")
    fig.suptitle(title)
    return fig


def plot_history(
    history: list[dict],
    path: str | Path,
    title: str = "",
    metric: str = "validation metric",
    best_epoch: int | None = None,
) -> Path:
    """:func:`history_figure` saved as a PNG at ``path`` (atomically)."""
    return save_figure(history_figure(history, title, metric, best_epoch), path, dpi=100)
