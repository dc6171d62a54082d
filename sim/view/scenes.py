"""One sample ready for a 3D view: the part, its taxels' pressure and labels, and the contactor's
geoms (hand, object, body part) where they were at the sample's frame.

A `ViewScene` gathers what a picture needs (part, per-taxel pressure and labels, contactor geoms
in the link frame = MuJoCo world frame, m). `simulate_scene` runs sample ``index`` of a dataset
configuration with the real runner (`sim.generate.sampler.sample_at`), then replays the accepted
episode up to the selected frame to read the contactor's geom poses (the runner keeps no poses; see
`replay_geoms`). `sim.view.render.render_scene` draws a scene. Headless set-up: docs/viewing.md.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import mujoco
import numpy as np

from sim.episode import press
from sim.episode.frames import read_frame, sensed_pressure
from sim.episode.runner import (
    CONTROL_DT_S,
    FRAME_DT_S,
    SENSOR_BIT,
    EpisodeContext,
    as_list,
    episode_rng,
    start_episode,
)
from sim.generate.config import GenerateConfig
from sim.generate.sampler import build_state, maker_at, sample_at
from sim.skin.parts import Part


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
    contact: int = 0  # which of the sample's contactors (0 for the first)


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
    model: mujoco.MjModel, data: mujoco.MjData, geom_labels: dict[str, int], contact: int = 0
) -> tuple[GeomShape, ...]:
    """The collision geoms of attached contactor ``contact`` (names ``press.prefix(contact) +
    key``) as placed in ``data`` (after mj_forward / mj_step)."""
    shapes = []
    for name, label in sorted(geom_labels.items()):
        g = model.geom(press.prefix(contact) + name).id
        kind = mujoco.mjtGeom(model.geom_type[g]).name.removeprefix("mjGEOM_").lower()
        shapes.append(
            GeomShape(
                kind,
                model.geom_size[g].copy(),
                data.geom_xpos[g].copy(),
                data.geom_xmat[g].reshape(3, 3).copy(),
                int(label),
                contact,
            )
        )
    return tuple(shapes)


def replay_geoms(
    ctx: EpisodeContext, contactor, plan, rng: np.random.Generator, frame_index: int
) -> tuple[tuple[GeomShape, ...], np.ndarray]:
    """Re-run an episode as `sim.episode.runner.run_episode` does (same rng state after ``make``) up
    to frame ``frame_index`` (0-based, 10 Hz) and return (contactor geoms, pressure (N,) Pa there);
    ``contactor`` and ``plan`` may be lists (several contacts).

    The pressure lets the caller check the replay against the stored sample."""
    start = start_episode(ctx, contactor, plan, rng)
    scene, contactors, plans = start.scene, as_list(contactor), as_list(plan)
    m, d = scene.model, scene.data
    n_ctrl = max(1, round(CONTROL_DT_S / m.opt.timestep))
    per_frame = round(FRAME_DT_S / CONTROL_DT_S)
    for k in range(frame_index + 1):
        m.opt.disableflags |= SENSOR_BIT
        for j in range(per_frame):
            press.apply_controls(scene, plans, (k * per_frame + j) * CONTROL_DT_S)
            mujoco.mj_step(m, d, nstep=n_ctrl)
        m.opt.disableflags &= ~SENSOR_BIT
        mujoco.mj_forward(m, d)
    frame = read_frame(scene, ctx.skin, ctx.cfg.active_pa, (frame_index + 1) * FRAME_DT_S)
    geoms = [contactor_geoms(m, d, c.geom_labels, k) for k, c in enumerate(contactors)]
    return tuple(g for shapes in geoms for g in shapes), frame.pressure_pa


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
    state = build_state(cfg)
    sample, rejects = sample_at(index, state)
    rng, _ = episode_rng(cfg.seed, index, sum(rejects.values()))
    contactor, plan = maker_at(index, state)(rng)
    frame_index = round(float(sample["time_s"]) / FRAME_DT_S) - 1
    geoms, pressure = replay_geoms(state.ctx, contactor, plan, rng, frame_index)
    if np.abs(pressure - sample["pressure_pa"]).max() > 1.0:
        raise RuntimeError(f"replay of sample {index} (seed {cfg.seed}) differs from the run")
    scene = ViewScene(
        state.ctx.part,
        sample["pressure_pa"].astype(np.float64),
        sample["taxel_label"].astype(np.int64),
        geoms,
        " + ".join(c.kind for c in as_list(contactor)),
        caption(sample, index),
    )
    return Simulated(scene, sample, state.ctx)


def sequence_pressure(ctx: EpisodeContext, seq_raw: np.ndarray, length: int) -> np.ndarray:
    """Pressure (T, N) Pa of the first ``length`` frames of ``seq_raw`` (T', N) counts, read as
    the robot reads them (`sim.episode.frames.sensed_pressure`: baseline, drift and 4 noise sd
    removed; frames at 10 Hz)."""
    return np.stack(
        [
            sensed_pressure(ctx.skin, raw, (k + 1) * FRAME_DT_S)
            for k, raw in enumerate(seq_raw[:length])
        ]
    )


def caption(sample: dict, index: int) -> str:
    """``#i kind name, F N`` from a sample dict's ``contactor`` JSON and ``force_n``."""
    descs = json.loads(str(sample.get("contactor", "{}")) or "{}")
    names = []
    for desc in descs if isinstance(descs, list) else [descs]:
        name = desc.get("subject") or desc.get("type") or desc.get("name", "")
        names.append(f"{desc.get('kind', '')} {name}".strip())
    force = float(sample.get("force_n", np.nan))
    return f"#{index} {' + '.join(names)}, {force:.1f} N".strip()
