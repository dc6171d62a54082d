"""Drawing a `sim.view.scenes.ViewScene` with pyvista: the link, the skin coloured by pressure, true
labels or predicted labels, and the contactor in place; off-screen, returning the RGB picture.

Headless set-up (an off-screen OpenGL): docs/viewing.md.
"""

from __future__ import annotations

import matplotlib.colors as mcolors
import numpy as np
import pyvista as pv

from sim.view.pictures import polydata
from sim.view.scenes import GeomShape, ViewScene
from tactile.images.labels import PALETTE

COLORS = ("pressure", "label", "prediction")
PANELS = ("contact", "skin")  # contactor in place; the skin alone (what it felt)
SKIN_RGB = (0.93, 0.76, 0.65)  # hand / body tissue colour
OBJECT_RGB = (0.85, 0.55, 0.25)
IDLE_RGB = "#c9d8ee"  # sensor mesh where nothing is felt
LINK_RGB = "#d9d9de"
SCALAR_BAR = {
    "title": "kPa",
    "vertical": True,
    "below_label": "idle",
    "fmt": "%.0f",
    "color": "black",
    "position_x": 0.87,
    "position_y": 0.15,
    "height": 0.6,
    "width": 0.06,
}


def geom_mesh(g: GeomShape):
    """pyvista PolyData of one primitive in the link frame (m)."""
    s = g.size_m
    if g.kind == "sphere":
        mesh = pv.Sphere(radius=s[0], theta_resolution=24, phi_resolution=16)
    elif g.kind == "capsule":
        mesh = pv.Capsule(radius=s[0], cylinder_length=2 * s[1], direction=(0, 0, 1), resolution=24)
    elif g.kind == "cylinder":
        mesh = pv.Cylinder(radius=s[0], height=2 * s[1], direction=(0, 0, 1), resolution=32)
    elif g.kind == "box":
        mesh = pv.Box(bounds=(-s[0], s[0], -s[1], s[1], -s[2], s[2]))
    elif g.kind == "ellipsoid":
        mesh = pv.ParametricEllipsoid(*s)
    else:
        raise ValueError(
            f"cannot draw geom type {g.kind!r}; known: sphere capsule cylinder box ellipsoid"
        )
    transform = np.eye(4)
    transform[:3, :3], transform[:3, 3] = g.rot, g.pos_m
    return mesh.triangulate().transform(transform, inplace=False)


def taxel_rgb(labels: np.ndarray) -> np.ndarray:
    """(N, 3) float 0..1 colours: PALETTE for classes 1..6, the idle colour for 0."""
    rgb = PALETTE[np.asarray(labels)] / 255.0
    return np.where(np.asarray(labels)[:, None] > 0, rgb, mcolors.to_rgb(IDLE_RGB))


def _add_skin(
    plotter, scene: ViewScene, color: str, labels: np.ndarray, active_pa: float, bar: bool
) -> None:
    layout = scene.part.layout
    lifted = layout.positions_m + 1.5e-3 * layout.normals
    skin = polydata(lifted, scene.part.sensor_faces)
    if color == "pressure":
        skin["pressure (kPa)"] = scene.pressure_pa / 1e3
        top = max(float(scene.pressure_pa.max()) / 1e3, 2 * active_pa / 1e3)
        plotter.add_mesh(
            skin,
            scalars="pressure (kPa)",
            cmap="inferno_r",
            clim=(active_pa / 1e3, top),
            below_color=IDLE_RGB,
            smooth_shading=True,
            show_scalar_bar=bar,
            scalar_bar_args=SCALAR_BAR,
        )
    else:
        skin["rgb"] = taxel_rgb(labels)
        plotter.add_mesh(skin, scalars="rgb", rgb=True, smooth_shading=True)


def _add_contactor(plotter, scene: ViewScene, by_label: bool) -> None:
    base = SKIN_RGB if scene.kind in ("hand", "body") else OBJECT_RGB
    opacity = 0.6 if scene.kind == "body" else 1.0  # a back or thigh would hide the whole arm
    for g in scene.geoms:
        rgb = PALETTE[g.label] / 255.0 if by_label and g.label > 0 else base
        plotter.add_mesh(
            geom_mesh(g), color=rgb, opacity=opacity, smooth_shading=True, specular=0.2
        )


def camera_direction(scene: ViewScene) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(focal point (3,) m, view vector (3,) from focus to camera, view-up (3,)) looking at the
    contact: along the pressure-weighted outward normal, tilted 35° along the link's width."""
    layout, w = scene.part.layout, np.maximum(scene.pressure_pa, 0.0)
    w = w if w.sum() > 0 else np.ones_like(w)
    normal = (layout.normals * w[:, None]).sum(axis=0)
    normal /= np.linalg.norm(normal)
    spread = layout.positions_m - layout.positions_m.mean(axis=0)
    axis = np.linalg.svd(spread, full_matrices=False)[2][0]  # the part's long axis
    side = np.cross(axis, normal)
    side /= max(np.linalg.norm(side), 1e-12)
    view = normal + 0.7 * side
    up = normal - np.dot(normal, view) / np.dot(view, view) * view
    at = (layout.positions_m * w[:, None]).sum(axis=0) / w.sum()
    return 0.3 * at + 0.7 * np.asarray(scene.part.link.bounds).mean(axis=0), view, up


def render_scene(
    scene: ViewScene,
    color: str = "pressure",
    predicted: np.ndarray | None = None,
    panels: tuple[str, ...] = PANELS,
    size_px: tuple[int, int] = (1200, 520),
    active_pa: float = 500.0,
    interactive: bool = False,
) -> np.ndarray:
    """Render ``scene`` (one sub-view per panel, same camera) and return the picture.

    color : "pressure" (kPa colour bar; idle below ``active_pa``, Pa), "label" (true classes,
    PALETTE) or "prediction" (``predicted`` (N,) int 0..6 per taxel, e.g. from
    `tactile.images.labels.backproject`). panels : "contact" draws the contactor in place over the
    skin, "skin" the skin alone. size_px : (width, height) pixels. Returns (H, W, 3) uint8.
    """
    if color not in COLORS:
        raise ValueError(f"color {color!r} unknown; choose one of {', '.join(COLORS)}")
    if color == "prediction" and predicted is None:
        raise ValueError("color='prediction' needs the predicted per-taxel labels")
    labels = predicted if color == "prediction" else scene.labels
    plotter = pv.Plotter(
        off_screen=not interactive, window_size=list(size_px), shape=(1, len(panels)), border=False
    )
    focus, view, up = camera_direction(scene)
    for i, panel in enumerate(panels):
        plotter.subplot(0, i)
        plotter.set_background("white")
        plotter.add_mesh(
            polydata(scene.part.link.vertices, scene.part.link.faces),
            color=LINK_RGB,
            smooth_shading=True,
            ambient=0.3,
        )
        _add_skin(plotter, scene, color, np.asarray(labels), active_pa, bar=panel == "skin")
        if panel == "contact":
            _add_contactor(plotter, scene, color != "pressure")
        distance = 1.5 * float(np.linalg.norm(np.ptp(scene.part.link.bounds, axis=0)))
        unit = view / np.linalg.norm(view)
        plotter.camera_position = [tuple(focus + distance * unit), tuple(focus), tuple(up)]
        text = scene.title if panel == "contact" else f"skin: {color}"
        plotter.add_text(text, font_size=9, color="black")
    image = (
        plotter.show(screenshot=True, return_img=True)
        if interactive
        else plotter.screenshot(return_img=True)
    )
    plotter.close()
    return np.asarray(image)[..., :3]
