"""Figures from arrays (matplotlib `Figure` API, no pyplot state, no display needed).

- `sample_panel`: the paper's Fig. 1 in our data — a 3D view (an RGB array, e.g. from
  `sim.view.scenes.render_scene`), the flat map with its triangles and taxel pressures, the tactile
  image and the label image.
- `sequence_strip` / `save_sequence_gif`: the 10 Hz frames of one interaction.
- `prediction_figure`: image, predicted segmentation, errors in red (Figs. 12–13).
- `part_bars_figure`: per-part mean pressure and taxel count (Fig. 18).
- `figure_to_array`: any Figure as an (H, W, 3) uint8 picture (tests, GIFs, compositing).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from PIL import Image

from tactile import files
from tactile.errors import MapError
from tactile.figures.sheet import overlay
from tactile.images.labels import CLASS_NAMES, PALETTE, part_summary

if TYPE_CHECKING:
    from tactile.images.tactile_map import TactileMap

ERROR_RGB = np.array([255, 0, 0], dtype=np.uint8)


def figure_to_array(fig: Figure, dpi: float = 100) -> np.ndarray:
    """Rasterise ``fig`` (Agg) at ``dpi`` dots/inch. Returns (H, W, 3) uint8 RGB."""
    canvas = FigureCanvasAgg(fig)
    fig.set_dpi(dpi)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()


def trim_background(rgb: np.ndarray, pad_px: int = 6) -> np.ndarray:
    """Crop the uniform border (the colour of the corner pixel) of an (H, W, 3) picture, keeping
    ``pad_px`` pixels around the content. Returns a view; the input when it is all background."""
    rgb = np.asarray(rgb)
    content = np.any(rgb != rgb[0, 0], axis=-1)
    if not content.any():
        return rgb
    rows, cols = np.flatnonzero(content.any(axis=1)), np.flatnonzero(content.any(axis=0))
    r0, c0 = max(rows[0] - pad_px, 0), max(cols[0] - pad_px, 0)
    return rgb[r0 : rows[-1] + pad_px + 1, c0 : cols[-1] + pad_px + 1]


def save_figure(fig: Figure, path: str | Path, dpi: float = 100) -> Path:
    """Write ``fig`` to ``path`` (PNG) atomically, creating the folder. Returns the path."""
    return files.save_figure(fig, path, dpi=dpi)


def palette_legend(fig: Figure, ncols: int = 6) -> None:
    """The six hand-part colours (PALETTE, paper's Fig. 10) as a legend under ``fig``."""
    handles = [Patch(color=PALETTE[c] / 255.0, label=n) for c, n in enumerate(CLASS_NAMES)]
    fig.legend(handles=handles[1:], loc="outside lower center", ncols=ncols, fontsize=8)


def draw_map_pressure(ax: Axes, tmap: TactileMap, pressure_pa: np.ndarray | None = None) -> None:
    """The flat map's triangles (grey edges) and taxels (grey dots), the pressed ones (p > 0)
    coloured by pressure when given. pressure_pa : (N,) float, Pa (kPa on the colour bar)."""
    tris = PolyCollection(
        tmap.vertex_uv_mm[tmap.faces], facecolors="0.95", edgecolors="0.65", linewidths=0.3
    )
    ax.add_collection(tris)
    placed = np.isfinite(tmap.uv[:, 0])
    ax.plot(*tmap.uv[placed].T, ".", ms=1.5, color="0.45")
    if pressure_pa is not None:
        kpa = np.where(placed, np.asarray(pressure_pa, dtype=float), 0.0) / 1e3
        on = np.flatnonzero(kpa > 0)
        on = on[np.argsort(kpa[on])]  # the most pressed on top
        dots = ax.scatter(
            *tmap.uv[on].T,
            c=kpa[on],
            s=10,
            cmap="inferno_r",
            vmin=0,
            vmax=max(float(kpa.max()), 1e-3),
            linewidths=0,
        )
        ax.figure.colorbar(dots, ax=ax, fraction=0.035, pad=0.02, label="pressure (kPa)")
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("u (mm)")
    ax.set_ylabel("v (mm)")


def _show(ax: Axes, picture: np.ndarray, title: str) -> None:
    ax.imshow(picture, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
    ax.set_title(title, fontsize=9)
    ax.set_axis_off()


def sample_panel(
    view_rgb: np.ndarray | None,
    tmap: TactileMap,
    image: np.ndarray,
    label_image: np.ndarray | None = None,
    pressure_pa: np.ndarray | None = None,
    title: str = "",
) -> Figure:
    """Fig. 1 of the paper for one sample: the 3D view on top; map with triangles, tactile image
    and labels below.

    view_rgb : (h, w, 3) uint8 3D picture or None (row left out). image : (H, W) uint8 tactile
    image on ``tmap``'s grid. label_image : (H, W) int classes 0..6 (None: panel left out).
    pressure_pa : (N,) float per-taxel pressure, Pa, for the map panel.
    """
    if np.shape(image) != tmap.shape:
        raise MapError(f"image shape {np.shape(image)} differs from the map's {tmap.shape}")
    view_rgb = None if view_rgb is None else trim_background(view_rgb)
    n = 2 + (label_image is not None)
    h, w = tmap.shape
    row_in = 13.0 / n * h / w + 0.9
    view_in = 0.0 if view_rgb is None else 13.0 * view_rgb.shape[0] / view_rgb.shape[1]
    fig = Figure(figsize=(13.0, view_in + row_in + 0.6), layout="constrained")
    grid = fig.add_gridspec(
        1 + (view_rgb is not None), n, height_ratios=[r for r in (view_in, row_in) if r > 0]
    )
    if view_rgb is not None:
        _show(fig.add_subplot(grid[0, :]), np.asarray(view_rgb), "")
    axes = [fig.add_subplot(grid[-1, k]) for k in range(n)]
    draw_map_pressure(axes[0], tmap, pressure_pa)
    axes[0].set_title(f"tactile map: {len(tmap.faces)} triangles", fontsize=9)
    _show(axes[1], image, f"tactile image {h} × {w} px ({tmap.step_mm:g} mm/px)")
    if label_image is not None:
        none = "" if np.any(label_image) else " (none: not a hand)"
        _show(axes[2], overlay(np.asarray(image), np.asarray(label_image)), "labels" + none)
        palette_legend(fig)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def common_scale_images(tmap: TactileMap, pressure: np.ndarray) -> np.ndarray:
    """Tactile images of a sequence on one intensity scale (the sequence's maximum = 255), so
    that frames with little or no contact stay dark (the paper's per-frame scaling would stretch
    their noise to full white). pressure : (T, N) float, any unit. Returns (T, H, W) uint8."""
    fields = np.clip(tmap.interpolate(np.asarray(pressure, dtype=np.float64)), 0.0, None)
    top = float(fields.max())
    return (
        np.floor(255.0 * fields / top + 1e-9).astype(np.uint8)
        if top > 0
        else np.zeros(fields.shape, np.uint8)
    )


def sequence_frames_rgb(images: np.ndarray, scale: int = 1) -> np.ndarray:
    """(T, H, W) uint8 tactile images -> (T, H*scale, W*scale, 3) uint8 grey RGB frames."""
    images = np.asarray(images)
    if images.ndim != 3 or not len(images):
        raise MapError(f"images must be a non-empty (T, H, W) stack, got shape {images.shape}")
    big = images.repeat(scale, axis=1).repeat(scale, axis=2)
    return np.repeat(big[..., None], 3, axis=3)


def sequence_strip(
    images: np.ndarray,
    times_s: Sequence[float] | None = None,
    *,
    title: str = "",
    max_frames: int = 12,
    tile_in: float = 1.8,
) -> Figure:
    """The frames of one interaction side by side (at most ``max_frames``, evenly picked).

    images : (T, H, W) uint8 tactile images at 10 Hz. times_s : (T,) frame times, s (default
    0.1·(k+1)). Each tile is captioned with its time and its maximum intensity (use
    `common_scale_images` to compare frames).
    """
    images = np.asarray(images)
    sequence_frames_rgb(images[:1])  # validates the shape
    times = np.asarray(times_s if times_s is not None else 0.1 * (np.arange(len(images)) + 1))
    pick = np.unique(np.linspace(0, len(images) - 1, min(max_frames, len(images))).round())
    pick = pick.astype(int)
    aspect = images.shape[1] / images.shape[2]
    fig = Figure(figsize=(tile_in * len(pick), tile_in * aspect + 0.7), layout="constrained")
    for ax, k in zip(np.atleast_1d(fig.subplots(1, len(pick))), pick, strict=True):
        _show(ax, images[k], f"t = {times[k]:.1f} s, max {int(images[k].max())}")
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def save_sequence_gif(
    path: str | Path, images: np.ndarray, *, fps: float = 10.0, scale: int = 1
) -> Path:
    """Animated GIF of (T, H, W) uint8 tactile images at ``fps`` frames/s (10 Hz = real time),
    each pixel enlarged ``scale`` times; loops forever. Returns the path."""
    frames = [Image.fromarray(f) for f in sequence_frames_rgb(images, scale)]
    return files.save_image(
        frames[0],
        path,
        save_all=True,
        append_images=frames[1:],
        loop=0,
        duration=round(1000.0 / fps),
        optimize=True,
    )


def error_picture(image: np.ndarray, true: np.ndarray, pred: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8: the tactile image in grey, pixels where ``pred != true`` in red.

    image : (H, W) uint8. true, pred : (H, W) int classes 0..6."""
    grey = np.repeat(np.asarray(image)[..., None], 3, axis=2)
    wrong = np.asarray(true) != np.asarray(pred)
    return np.where(wrong[..., None], ERROR_RGB, grey).astype(np.uint8)


def prediction_figure(
    image: np.ndarray,
    true: np.ndarray | None,
    pred: np.ndarray,
    *,
    title: str = "",
    pred_name: str = "predicted",
) -> Figure:
    """Original image | true labels | predicted segmentation | errors in red (Figs. 12–13).

    image : (H, W) uint8. true : (H, W) int classes 0..6, or None when the ground truth is
    unknown (then only image | predicted). pred : (H, W) int classes 0..6. The error panel's
    title gives the pixel accuracy over the tactile image's foreground (image > 0 or either
    label > 0). Panels are 13/4 inches wide each.
    """
    image, pred = np.asarray(image), np.asarray(pred)
    if image.shape != pred.shape or (true is not None and np.shape(true) != image.shape):
        raise MapError(
            f"image {image.shape}, true {np.shape(true) if true is not None else None}"
            f" and pred {pred.shape} differ"
        )
    n = 2 if true is None else 4
    fig = Figure(
        figsize=(13 / 4 * n, 1.0 + 13 / 4 * image.shape[0] / image.shape[1]), layout="constrained"
    )
    axes = fig.subplots(1, n)
    _show(axes[0], image, "tactile image")
    _show(axes[1 if true is None else 2], overlay(image, pred), pred_name)
    if true is not None:
        true = np.asarray(true)
        fg = (image > 0) | (true > 0) | (pred > 0)
        acc = float((true[fg] == pred[fg]).mean()) if fg.any() else 1.0
        _show(axes[1], overlay(image, true), "true labels")
        _show(
            axes[3], error_picture(image, true, pred), f"errors (red), accuracy {100 * acc:.1f} %"
        )
    palette_legend(fig, ncols=6 if n == 4 else 3)
    if title:
        fig.suptitle(title, fontsize=10)
    return fig


def part_bars_figure(
    labels: np.ndarray | None,
    pressure_pa: np.ndarray,
    *,
    pred_labels: np.ndarray | None = None,
    threshold_pa: float = 0.0,
    title: str = "",
) -> Figure:
    """Per hand part: mean pressure (kPa) and pressed taxel count, bars in PALETTE (Fig. 18).

    labels, pred_labels : (N,) int per-taxel classes 0..6 (true / predicted, e.g. back-projected
    with `tactile.images.labels.backproject`); either may be None, not both. pressure_pa : (N,)
    float, Pa. threshold_pa : a taxel counts when its pressure exceeds it, Pa. Predicted bars are
    hatched; with both series, a legend tells them apart.
    """
    series = [
        (name, lab, k)
        for k, (name, lab) in enumerate((("true", labels), ("predicted", pred_labels)))
        if lab is not None
    ]
    if not series:
        raise MapError("part_bars_figure needs true labels, predicted labels or both")
    names = CLASS_NAMES[1:]
    x, width = np.arange(len(names)), 0.8 / len(series)
    fig = Figure(figsize=(10, 3.6), layout="constrained")
    ax_p, ax_n = fig.subplots(1, 2)
    for j, (name, lab, hatched) in enumerate(series):
        summary = part_summary(lab, pressure_pa, threshold=threshold_pa)
        kw = {
            "color": PALETTE[1:] / 255.0,
            "edgecolor": "k",
            "linewidth": 0.5,
            "hatch": "//" if hatched else None,
            "label": name,
        }
        offset = x + (j - (len(series) - 1) / 2) * width
        ax_p.bar(offset, [summary[n].mean_pressure / 1e3 for n in names], width, **kw)
        ax_n.bar(offset, [summary[n].n_taxels for n in names], width, **kw)
    for ax, label in ((ax_p, "mean pressure (kPa)"), (ax_n, "pressed taxels (count)")):
        ax.set_xticks(x, names, fontsize=8)
        ax.set_xlabel("hand part")
        ax.set_ylabel(label)
        ax.grid(axis="y", alpha=0.3)
        ax.legend(
            handles=[
                Patch(facecolor="w", edgecolor="k", hatch="//" if h else None, label=name)
                for name, _, h in series
            ],
            fontsize=8,
        )
    if title:
        fig.suptitle(title, fontsize=10)
    return fig
