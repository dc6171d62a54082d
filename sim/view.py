"""3D views of one sample: the part, its taxels coloured by pressure / label / prediction, and the
contactor's geoms (hand, object, body part) drawn where they were at the sample's frame.

A `ViewScene` gathers what a picture needs (part, per-taxel pressure and labels, contactor geoms
in the link frame = MuJoCo world frame, m). `simulate_scene` runs sample ``index`` of a dataset
configuration with the real runner (`sim.sampler.sample_at`), then replays the accepted episode
up to the selected frame to read the contactor's geom poses (the runner keeps no poses; see
`replay_geoms`). `render_scene` draws it with pyvista off-screen and returns the RGB picture.
Headless set-up: docs/viewing.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from sim import press
from sim.episode import (
    CONTROL_DT_S,
    FRAME_DT_S,
    SENSOR_BIT,
    EpisodeContext,
    episode_rng,
    site_pose,
)
from sim.episode_frames import read_frame
from sim.gen_config import GenerateConfig
from sim.parts import Part
from tactile.labels import PALETTE

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


@dataclass(frozen=True)
class GeomShape:
    """One contactor primitive in the link frame.

    kind : MuJoCo geom type name ("sphere", "capsule", "cylinder", "box", "ellipsoid").
    size_m : (3,) MuJoCo geom size, m. pos_m : (3,) centre, m. rot : (3, 3) geom-to-link
    rotation. label : class 0..6 of the geom (0 for non-hand parts).
    """

    kind: str
    size_m: np.ndarray
    pos_m: np.ndarray
    rot: np.ndarray
    label: int


@dataclass(frozen=True, eq=False)
class ViewScene:
    """A sample ready to draw. pressure_pa : (N,) float, Pa. labels : (N,) int 0..6 (true).
    geoms : the contactor at the sample's frame (empty when unknown, e.g. a real recording).
    kind : "hand" | "object" | "body" | "". title : one-line caption."""

    part: Part
    pressure_pa: np.ndarray
    labels: np.ndarray
    geoms: tuple[GeomShape, ...]
    kind: str = ""
    title: str = ""


def contactor_geoms(
    model: mujoco.MjModel, data: mujoco.MjData, geom_labels: dict[str, int]
) -> tuple[GeomShape, ...]:
    """The collision geoms of the attached contactor (names ``press.PREFIX + key``) as placed in
    ``data`` (after mj_forward / mj_step)."""
    shapes = []
    for name, label in sorted(geom_labels.items()):
        g = model.geom(press.PREFIX + name).id
        kind = mujoco.mjtGeom(model.geom_type[g]).name.removeprefix("mjGEOM_").lower()
        shapes.append(
            GeomShape(
                kind,
                model.geom_size[g].copy(),
                data.geom_xpos[g].copy(),
                data.geom_xmat[g].reshape(3, 3).copy(),
                int(label),
            )
        )
    return tuple(shapes)


def replay_geoms(
    ctx: EpisodeContext, contactor, plan, rng: np.random.Generator, frame_index: int
) -> tuple[tuple[GeomShape, ...], np.ndarray]:
    """Re-run an episode as `sim.episode.run_episode` does (same rng state after ``make``) up to
    frame ``frame_index`` (0-based, 10 Hz) and return (contactor geoms, pressure (N,) Pa there).

    The pressure lets the caller check the replay against the stored sample."""
    scene = ctx.scene(contactor)
    m, d = scene.model, scene.data
    _, pos, quat = site_pose(ctx, plan, rng)
    press.reset(scene, plan, pos, quat)
    n_ctrl = max(1, round(CONTROL_DT_S / m.opt.timestep))
    per_frame = round(FRAME_DT_S / CONTROL_DT_S)
    for k in range(frame_index + 1):
        m.opt.disableflags |= SENSOR_BIT
        for j in range(per_frame):
            press.apply_controls(scene, plan, (k * per_frame + j) * CONTROL_DT_S)
            mujoco.mj_step(m, d, nstep=n_ctrl)
        m.opt.disableflags &= ~SENSOR_BIT
        mujoco.mj_forward(m, d)
    frame = read_frame(scene, ctx.skin, ctx.cfg.active_pa, (frame_index + 1) * FRAME_DT_S)
    return contactor_geoms(m, d, contactor.geom_labels), frame.pressure_pa


@dataclass(frozen=True, eq=False)
class Simulated:
    """A sample simulated now: its ViewScene, the dataset sample dict and the episode context
    (part, tactile map, skin instance) that made it."""

    scene: ViewScene
    sample: dict
    ctx: EpisodeContext


def simulate_scene(cfg: GenerateConfig, index: int) -> Simulated:
    """Sample ``index`` of configuration ``cfg``, simulated now with the contactor's geoms.

    Raises RuntimeError if the replayed frame's pressure differs from the sample's (> 1 Pa)."""
    from sim.generate import is_hand_index
    from sim.sampler import build_state, sample_at

    state = build_state(cfg)
    sample, rejects = sample_at(index, state)
    make = state.hand if is_hand_index(index, cfg.hand_fraction) else state.nonhand
    rng, _ = episode_rng(cfg.seed, index, sum(rejects.values()))
    contactor, plan = make(rng)
    frame_index = round(float(sample["time_s"]) / FRAME_DT_S) - 1
    geoms, pressure = replay_geoms(state.ctx, contactor, plan, rng, frame_index)
    if np.abs(pressure - sample["pressure_pa"]).max() > 1.0:
        raise RuntimeError(f"replay of sample {index} (seed {cfg.seed}) differs from the run")
    scene = ViewScene(
        state.ctx.part,
        sample["pressure_pa"].astype(np.float64),
        sample["taxel_label"].astype(np.int64),
        geoms,
        contactor.kind,
        caption(sample, index),
    )
    return Simulated(scene, sample, state.ctx)


def sequence_pressure(ctx: EpisodeContext, seq_raw: np.ndarray, length: int) -> np.ndarray:
    """Pressure (T, N) Pa of the first ``length`` frames of ``seq_raw`` (T', N) counts, read as
    the robot reads them (`sim.episode_frames.sensed_pressure`: baseline, drift and 3 noise sd
    removed; frames at 10 Hz)."""
    from sim.episode_frames import sensed_pressure

    return np.stack(
        [
            sensed_pressure(ctx.skin, raw, (k + 1) * FRAME_DT_S)
            for k, raw in enumerate(seq_raw[:length])
        ]
    )


def caption(sample: dict, index: int) -> str:
    """``#i kind name, F N`` from a sample dict's ``contactor`` JSON and ``force_n``."""
    import json

    desc = json.loads(str(sample.get("contactor", "{}")) or "{}")
    name = desc.get("subject") or desc.get("type") or desc.get("name", "")
    force = float(sample.get("force_n", np.nan))
    return f"#{index} {desc.get('kind', '')} {name}, {force:.1f} N".strip()


# --- drawing ------------------------------------------------------------------------------------


def geom_mesh(g: GeomShape):
    """pyvista PolyData of one primitive in the link frame (m)."""
    import pyvista as pv

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
    import matplotlib.colors as mcolors

    rgb = PALETTE[np.asarray(labels)] / 255.0
    return np.where(np.asarray(labels)[:, None] > 0, rgb, mcolors.to_rgb(IDLE_RGB))


def _poly(vertices: np.ndarray, faces: np.ndarray):
    import pyvista as pv

    return pv.PolyData(vertices, np.column_stack([np.full(len(faces), 3), faces]).ravel())


def _add_skin(
    plotter, scene: ViewScene, color: str, labels: np.ndarray, active_pa: float, bar: bool
) -> None:
    layout = scene.part.layout
    lifted = layout.positions_m + 1.5e-3 * layout.normals
    skin = _poly(lifted, scene.part.sensor_faces)
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
    `tactile.labels.backproject`). panels : "contact" draws the contactor in place over the
    skin, "skin" the skin alone. size_px : (width, height) pixels. Returns (H, W, 3) uint8.
    """
    import pyvista as pv

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
            _poly(scene.part.link.vertices, scene.part.link.faces),
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
