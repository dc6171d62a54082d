"""Pictures of tactile maps (matplotlib, off-screen): flat mesh, taxels, holes, distortion.

Uses the object-oriented `Figure` API, so no global backend is set and no display is needed.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from matplotlib.axes import Axes
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure

from tactile.files import save_figure

if TYPE_CHECKING:
    from tactile.images.tactile_map import TactileMap


def coverage_mask(tmap: TactileMap) -> np.ndarray:
    """Pixels inside the flat mesh.

    Returns
    -------
    mask : (H, W) bool — True where the grid point lies in a triangle of the map.
    """
    return tmap.interpolate(np.ones(tmap.n_taxels)) > 0.5


def draw_mesh(ax: Axes, tmap: TactileMap, *, color_by_area: bool = True) -> None:
    """Draw the flat triangles (coloured by 2D/3D area ratio) and the taxels on ``ax``."""
    tris = tmap.vertex_uv_mm[tmap.faces]
    ratio = tmap.distortion.area_ratio
    coll = PolyCollection(tris, edgecolors="0.35", linewidths=0.3, cmap="coolwarm")
    if color_by_area:
        coll.set_array(np.log2(np.clip(ratio, 1e-3, None)))
        coll.set_clim(-0.5, 0.5)
    else:
        coll.set_facecolor("0.85")
    ax.add_collection(coll)
    placed = np.isfinite(tmap.uv[:, 0])
    ax.plot(*tmap.uv[placed].T, ".", ms=2.0, color="k")
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("u (mm)")
    ax.set_ylabel("v (mm)")
    if color_by_area:
        cb = ax.figure.colorbar(coll, ax=ax, fraction=0.03, pad=0.02)
        cb.set_label("log2(area 2D / area 3D)")


def map_figure(tmap: TactileMap, title: str = "") -> Figure:
    """A two-panel figure: the flat mesh with its taxels, and the pixel coverage (holes black)."""
    h, w = tmap.shape
    fig = Figure(figsize=(13, 5.2), layout="constrained")
    axes = fig.subplots(1, 2)
    draw_mesh(axes[0], tmap)
    n_unplaced = int(np.sum(~np.isfinite(tmap.uv[:, 0])))
    axes[0].set_title(
        f"flat mesh: {tmap.n_taxels} taxels ({n_unplaced} unplaced), {len(tmap.faces)} triangles"
    )
    axes[1].imshow(coverage_mask(tmap), cmap="gray", interpolation="nearest")
    axes[1].set_title(f"grid {h} × {w} px at {tmap.step_mm:g} mm (black: no coverage)")
    axes[1].set_xlabel("column (u)")
    axes[1].set_ylabel("row (v)")
    if title:
        fig.suptitle(title)
    return fig


def save_map_picture(tmap: TactileMap, path: str | Path, title: str = "") -> Path:
    """Write :func:`map_figure` to ``path`` (PNG) and return the path."""
    return save_figure(map_figure(tmap, title), path, dpi=110)
