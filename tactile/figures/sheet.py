"""Contact sheets: a grid of tactile images (and their label images) with titles and a legend.

Works on arrays, so synthetic datasets, real recordings and in-memory samples share it.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure
from matplotlib.patches import Patch

from tactile.errors import MapError
from tactile.files import save_figure
from tactile.images.labels import CLASS_NAMES, PALETTE, colorize


def _check(images: np.ndarray, labels: np.ndarray | None, titles: Sequence[str] | None) -> None:
    if images.ndim != 3 or len(images) == 0:
        raise MapError(f"images must be a non-empty (B, H, W) stack, got shape {images.shape}")
    if labels is not None and labels.shape != images.shape:
        raise MapError(f"labels shape {labels.shape} must equal images shape {images.shape}")
    if titles is not None and len(titles) != len(images):
        raise MapError(f"{len(titles)} titles for {len(images)} images: give one title per image")


def overlay(image: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """Label colours shaded by the tactile image's intensity.

    image : (H, W) uint8; labels : (H, W) int classes. Returns (H, W, 3) uint8 RGB: grey where the
    label is background, the class colour (PALETTE) scaled by 0.35 + 0.65·I/255 elsewhere.
    """
    grey = np.repeat(image[..., None], 3, axis=2).astype(np.float64)
    shade = 0.35 + 0.65 * image[..., None] / 255.0
    coloured = colorize(labels).astype(np.float64) * shade
    return np.where(labels[..., None] > 0, coloured, grey).astype(np.uint8)


INSTANCE_COLOURS = ("white", "cyan", "yellow", "magenta")  # outline of contact 1, 2, ...


def contact_sheet(
    images: np.ndarray,
    labels: np.ndarray | None = None,
    titles: Sequence[str] | None = None,
    *,
    instances: np.ndarray | None = None,
    n_cols: int = 6,
    title: str = "",
    tile_in: float = 2.2,
) -> Figure:
    """A grid of samples; with ``labels``, each tile shows the label colours over the image.

    images : (B, H, W) uint8 tactile images. labels : (B, H, W) int classes (0..6) or None.
    titles : one short caption per tile. instances : (B, H, W) int contact per pixel (0 none,
    k + 1 contact k) or None; each contact is outlined in its colour (`INSTANCE_COLOURS`). The
    legend names the classes with the paper's palette.
    """
    images = np.asarray(images)
    _check(images, labels, titles)
    n_cols = max(1, min(n_cols, len(images)))
    n_rows = int(np.ceil(len(images) / n_cols))
    aspect = images.shape[1] / images.shape[2]
    fig = Figure(figsize=(n_cols * tile_in, n_rows * tile_in * aspect + 0.9), layout="constrained")
    axes = np.atleast_1d(fig.subplots(n_rows, n_cols, squeeze=False)).ravel()
    for k, ax in enumerate(axes):
        ax.set_axis_off()
        if k >= len(images):
            continue
        tile = images[k] if labels is None else overlay(images[k], np.asarray(labels[k]))
        ax.imshow(tile, cmap="gray", vmin=0, vmax=255, interpolation="nearest")
        if instances is not None:
            _outline(ax, np.asarray(instances[k]))
        if titles is not None:
            ax.set_title(titles[k], fontsize=7)
    if labels is not None:
        handles = [Patch(color=PALETTE[c] / 255.0, label=n) for c, n in enumerate(CLASS_NAMES)]
        fig.legend(handles=handles[1:], loc="outside lower center", ncols=6, fontsize=8)
    if title:
        fig.suptitle(title)
    return fig


def _outline(ax, contacts: np.ndarray) -> None:
    """Outline every contact (pixels k + 1 of ``contacts`` (H, W)) in its colour."""
    for k in range(1, int(contacts.max(initial=0)) + 1):
        if (contacts == k).any():
            colour = INSTANCE_COLOURS[(k - 1) % len(INSTANCE_COLOURS)]
            ax.contour(contacts == k, levels=[0.5], colors=[colour], linewidths=0.8)


def padded(arrays: Sequence[np.ndarray]) -> np.ndarray:
    """(B, H, W) stack of (h, w) arrays of one dtype, each at the top left of a zero canvas of the
    largest height and width: prints of different frames (real and simulated) on one sheet at the
    same scale (1 mm a pixel for both)."""
    if not arrays:
        raise MapError("no image to lay out: give at least one")
    h = max(a.shape[0] for a in arrays)
    w = max(a.shape[1] for a in arrays)
    out = np.zeros((len(arrays), h, w), dtype=np.asarray(arrays[0]).dtype)
    for k, a in enumerate(arrays):
        out[k, : a.shape[0], : a.shape[1]] = a
    return out


def save_contact_sheet(path: str | Path, images: np.ndarray, **kw: object) -> Path:
    """Write :func:`contact_sheet` to ``path`` (PNG); keyword arguments go to it."""
    return save_figure(contact_sheet(images, **kw), path, dpi=100)  # type: ignore[arg-type]
