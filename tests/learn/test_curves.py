"""Training curves: the loss and validation-metric figure, and the best epoch marked on it."""

from __future__ import annotations

from learn.train.curves import history_figure, plot_history


def test_plot_history(tmp_path):
    hist = [
        {"epoch": 1, "train_loss": 1.0, "val_loss": 0.9, "val_metric": 0.6},
        {"epoch": 2, "train_loss": 0.5, "val_loss": 0.7, "val_metric": 0.8},
    ]
    assert plot_history(hist, tmp_path / "c.png").stat().st_size > 1000
    metric_ax = history_figure(hist, best_epoch=2).axes[1]
    (star,) = [line for line in metric_ax.get_lines() if line.get_label().startswith("best.pt")]
    assert list(star.get_xdata()) == [2] and list(star.get_ydata()) == [0.8]
    assert "epoch 2, 0.8000" in star.get_label()
    unmarked = history_figure(hist).axes[1]  # no best epoch given (or none validated): no star
    assert not any(line.get_label().startswith("best.pt") for line in unmarked.get_lines())
