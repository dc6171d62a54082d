"""Pictures of parts and probe calibrations (off-screen: pyvista for 3D, matplotlib Figure API).

pyvista renders with VTK off-screen; without a display VTK may log "bad X server connection" and
still render (set-up without a display: docs/viewing.md).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyvista as pv
from matplotlib.figure import Figure

from sim.skin.parts import Part


def polydata(vertices: np.ndarray, faces: np.ndarray) -> pv.PolyData:
    """A pyvista triangle mesh: vertices (V, 3) float, m; faces (M, 3) int."""
    return pv.PolyData(vertices, np.column_stack([np.full(len(faces), 3), faces]).ravel())


VIEWS = {"+x": (1.0, -0.35, 0.35), "+y": (0.35, 1.0, 0.3), "-x": (-1.0, 0.35, 0.3)}


def save_part_picture(
    part: Part,
    path: str | Path,
    views: tuple[str, ...] = ("+x", "-x"),
    size_px: tuple[int, int] = (1000, 560),
) -> Path:
    """Render the link (grey), the sensor mesh (blue) and the taxels (coloured by module).

    The sensor mesh and taxels are drawn 1.5–2 mm out along the normals so that chords across
    rounded edges stay visible."""
    pv.OFF_SCREEN = True
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    plotter = pv.Plotter(off_screen=True, window_size=size_px, shape=(1, len(views)))
    pos, normals = part.layout.positions_m, part.layout.normals
    for i, view in enumerate(views):
        plotter.subplot(0, i)
        plotter.add_mesh(
            polydata(part.link.vertices, part.link.faces),
            color="#d9d9de",
            smooth_shading=True,
            ambient=0.3,
        )
        plotter.add_mesh(
            polydata(pos + 1.5e-3 * normals, part.sensor_faces),
            color="#a9c4ee",
            show_edges=True,
            edge_color="#35598f",
            line_width=0.6,
        )
        cloud = pv.PolyData(pos + 2e-3 * normals)
        cloud["module"] = part.layout.module_ids % 10
        plotter.add_mesh(
            cloud,
            scalars="module",
            cmap="tab10",
            point_size=6,
            render_points_as_spheres=True,
            show_scalar_bar=False,
        )
        plotter.view_vector(VIEWS[view], viewup=(0.0, 0.0, 1.0))
        plotter.add_text(f"{part.name}: {part.n_taxels} taxels, seen from {view}", font_size=9)
    plotter.screenshot(str(path))
    plotter.close()
    return path


def calibration_figure(curves: dict[str, dict[str, np.ndarray]], title: str = "") -> Figure:
    """Two panels: force vs summed signal (counts), force vs active taxels; one line per probe.

    curves : {probe label: `sim.episode.probe.calibration_curve` output}.
    """
    fig = Figure(figsize=(11, 4.2), layout="constrained")
    ax_sum, ax_act = fig.subplots(1, 2)
    for label, c in curves.items():
        (line,) = ax_sum.plot(c["force_n"], c["summed_signal_counts"] / 1e3, ".-", label=label)
        sat = c["saturated"] > 0
        ax_sum.plot(
            c["force_n"][sat],
            c["summed_signal_counts"][sat] / 1e3,
            "x",
            color=line.get_color(),
            ms=8,
        )
        ax_act.step(c["force_n"], c["active"], where="mid", label=label, color=line.get_color())
        ax_act.plot(c["force_n"], c["expected_active"], ":", color=line.get_color(), lw=2)
    ax_sum.set_xlabel("indenter force (N)")
    ax_sum.set_ylabel("summed reading above baseline (10³ counts)")
    ax_sum.set_title("force → total reading (×: a taxel at 65535)", fontsize=10)
    ax_act.set_xlabel("indenter force (N)")
    ax_act.set_ylabel("active taxels (depth > 0)")
    ax_act.set_title("force → active taxels (dotted: within contact radius)", fontsize=10)
    for ax in (ax_sum, ax_act):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=9)
    return fig
