"""One skin frame of an episode: depth, noise-free pressure, attribution, force; and the labels.

Functions on a compiled `sim.press.PressScene` after `mj_forward`, and pure functions on arrays
for the per-taxel labels (who pressed each active taxel, through the skin's spread kernel).
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from sim.press import PressScene
from sim.skin import SkinInstance, depth_to_pressure
from tactile.labels import label_image
from tactile.tactile_map import TactileMap

NOISE_SIGMAS = 3.0  # readings less than this many noise sd above the baseline are read as 0


@dataclass(frozen=True)
class Frame:
    """The skin at one sample time.

    depth_m, pressure_pa : (N,) float, m and Pa (noise-free, after the spread kernel).
    geom : (N,) int64 index into the scene's readout geoms of the deepest one, -1 none.
    geom_label : (N,) int64 class of that geom (0 where none or non-hand).
    active : taxels with pressure_pa above the active threshold. force_n : total normal force
    between contactor and link, N. time_s : time in the episode, s.
    """

    time_s: float
    depth_m: np.ndarray
    pressure_pa: np.ndarray
    geom: np.ndarray
    geom_label: np.ndarray
    active: int
    force_n: float


@dataclass(frozen=True)
class Frames:
    """The 10 Hz frames of one episode and the selected one (most active taxels, first of ties)."""

    frames: list[Frame]

    @property
    def best_index(self) -> int:
        return int(np.argmax([f.active for f in self.frames])) if self.frames else -1

    @property
    def best(self) -> Frame:
        return self.frames[self.best_index]

    @property
    def best_active(self) -> int:
        return self.best.active if self.frames else 0


def contact_force_n(scene: PressScene) -> float:
    """Sum of the normal forces (N) of the contacts between the link and anything else."""
    m, d = scene.model, scene.data
    link = scene.readout.link_body
    force, total = np.zeros(6), 0.0
    for i in range(d.ncon):
        g1, g2 = d.contact.geom[i]
        if (m.body_weldid[m.geom_bodyid[g1]] == link) != (m.body_weldid[m.geom_bodyid[g2]] == link):
            mujoco.mj_contactForce(m, d, i, force)
            total += force[0]
    return float(total)


def read_frame(scene: PressScene, skin: SkinInstance, active_pa: float, time_s: float) -> Frame:
    """The frame of the current state (call after `mj_forward` with sensors enabled)."""
    out = scene.readout.read(scene.model, scene.data)
    pressure = skin.pressure(out.depth_m)
    label = np.where(out.contactor >= 0, scene.geom_label[out.contactor], 0)
    active = int(np.count_nonzero(pressure > active_pa))
    return Frame(time_s, out.depth_m, pressure, out.contactor, label, active,
                 contact_force_n(scene))


def sensed_pressure(skin: SkinInstance, reading: np.ndarray, time_s: float) -> np.ndarray:
    """Pressure (N,) Pa as the robot reads it: reading minus the known baseline and drift,
    below `NOISE_SIGMAS` noise sd set to 0, over the nominal gain (gains unknown to it)."""
    signal = reading.astype(np.float64) - skin.offset(time_s)
    floor = NOISE_SIGMAS * skin.cfg.noise_std_counts
    return np.where(signal > floor, signal, 0.0) / skin.cfg.counts_per_pa


def label_taxels(
    skin: SkinInstance, frame: Frame, active_pa: float
) -> tuple[np.ndarray, np.ndarray]:
    """Per-taxel (class (N,) int64 0..6, contactor index (N,) int64, 0 or -1) of one frame.

    An active taxel (noise-free pressure above ``active_pa``) takes the class contributing most
    of its pressure through the spread kernel (attributed taxels' own pressure, by class), so
    taxels activated only by spreading inherit their neighbours' class; contactor index 0 (the
    sample's single contactor) where any attributed pressure reaches it, -1 elsewhere.
    """
    base = depth_to_pressure(frame.depth_m, skin.cfg) * (frame.geom >= 0)
    classes = np.arange(7)[:, None]
    parts = np.asarray(skin.spread @ (base[None, :] * (frame.geom_label == classes)).T).T
    reached = (frame.pressure_pa > active_pa) & (parts.sum(axis=0) > 0)
    label = np.where(reached, parts.argmax(axis=0), 0)
    return label.astype(np.int64), np.where(reached, 0, -1).astype(np.int64)


def tactile_images(
    tmap: TactileMap, sensed_pa: np.ndarray, labels: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(image, label image) of one frame, the tactile image made once.

    sensed_pa : (N,) float, Pa (`sensed_pressure`). labels : (N,) int 0..6 (`label_taxels`).
    Returns two (H, W) uint8 arrays, equal to ``tmap.image(sensed_pa)`` and
    ``tmap.label_image(sensed_pa, labels)``.
    """
    image = tmap.image(sensed_pa)
    return image, label_image(tmap, sensed_pa, labels, image=image)
