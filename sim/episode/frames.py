"""One skin frame of an episode: depth, noise-free pressure, attribution, force; and the labels.

Functions on a compiled `sim.episode.press.PressScene` after `mj_forward`, and pure functions on
arrays for the per-taxel labels (who pressed each active taxel, through the skin's spread kernel).

Pressure is force-consistent (`sim.skin.model`): the foundation field of the depths is scaled so
that its resultant equals the *sensed* normal force — the solver's force of the contacts between the
contactor and the link whose contact point lies within `SENSED_RADIUS_SPACINGS` taxel spacings of
a pressed taxel (contacts on bare link are not felt).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import mujoco
import numpy as np

from sim.episode.press import PressScene
from sim.skin.model import SkinInstance, depth_to_pressure
from sim.skin.readout import ContactSnapshot, LinkContacts, TaxelReadout, link_contacts
from tactile.images.labels import label_image
from tactile.images.tactile_map import TactileMap

# A contact is felt when its point lies within this many taxel spacings (`SkinInstance.spacing_m`,
# the pad pitch) of a pressed taxel: about one, plus the half pitch by which a flat face's rim
# contacts can lie beyond the last pressed taxel (a 25 mm punch on the plate: 1.0 pitch).
SENSED_RADIUS_SPACINGS = 1.5


@dataclass(frozen=True)
class Frame:
    """The skin at one sample time.

    depth_m, pressure_pa : (N,) float, m and Pa (noise-free, after the spread kernel).
    active : taxels with pressure_pa above the active threshold. force_n : total normal force
    between contactor and link, N. sensed_force_n : the part of it on the sensorized region
    (the resultant of ``pressure_pa``), N. time_s : time in the episode, s.
    snapshot, readout, geom_labels : what `geom` and `geom_label` are computed from, on first
    use (only the selected frame of an episode is attributed).
    """

    time_s: float
    depth_m: np.ndarray
    pressure_pa: np.ndarray
    active: int
    force_n: float
    sensed_force_n: float
    snapshot: ContactSnapshot
    readout: TaxelReadout
    geom_labels: np.ndarray  # (K,) int64 class of each readout contactor geom
    geom_contactors: np.ndarray  # (K,) int64 contactor of each readout geom (0 with one)

    @cached_property
    def geom(self) -> np.ndarray:
        """(N,) int64 index into the scene's readout geoms of the deepest one, -1 none."""
        return self.readout.attribute(self.snapshot)

    @cached_property
    def geom_label(self) -> np.ndarray:
        """(N,) int64 class of that geom (0 where none or non-hand)."""
        return np.where(self.geom >= 0, self.geom_labels[self.geom], 0)

    @cached_property
    def contactor(self) -> np.ndarray:
        """(N,) int64 contactor of that geom (-1 where none)."""
        return np.where(self.geom >= 0, self.geom_contactors[self.geom], -1)


@dataclass(frozen=True)
class Frames:
    """The 10 Hz frames of one episode and the selected one: most active taxels (first of ties)
    among the first ``n_select`` frames (load and hold; None: all), so frames simulated only for
    a kept sequence (release) never change the selection."""

    frames: list[Frame]
    n_select: int | None = None

    @property
    def best_index(self) -> int:
        eligible = self.frames[: self.n_select]
        return int(np.argmax([f.active for f in eligible])) if eligible else -1

    @property
    def best(self) -> Frame:
        return self.frames[self.best_index]

    @property
    def best_active(self) -> int:
        return self.best.active if self.frames else 0


def contact_forces_n(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    contacts: LinkContacts,
    pressed_m: np.ndarray,
    radius_m: float,
) -> tuple[float, float]:
    """(total, sensed) normal force (N) of the link's ``contacts``: all of them, and those whose
    point lies within ``radius_m`` (m) of a pressed taxel (world positions (K, 3), m)."""
    idx = contacts.index
    normal = _normal_forces_n(model, data, idx)
    if not idx.size or not len(pressed_m):
        return float(normal.sum()), 0.0
    points = np.asarray(data.contact.pos[: data.ncon])[idx]
    gap2 = np.min(np.sum((points[:, None, :] - pressed_m[None]) ** 2, axis=2), axis=1)
    return float(normal.sum()), float(normal[gap2 <= radius_m**2].sum())


def _normal_forces_n(model: mujoco.MjModel, data: mujoco.MjData, idx: np.ndarray) -> np.ndarray:
    """(C,) normal forces (N) of contacts ``idx``: the first constraint row of each contact with
    elliptic cones (as `mujoco.mj_contactForce` reads it), `mj_contactForce` otherwise."""
    adr = np.asarray(data.contact.efc_address[: data.ncon])[idx]
    if model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC:
        return np.where(adr >= 0, data.efc_force[np.maximum(adr, 0)], 0.0)
    force, normal = np.zeros(6), np.zeros(idx.size)
    for j, i in enumerate(idx):
        mujoco.mj_contactForce(model, data, int(i), force)
        normal[j] = force[0]
    return normal


def read_frame(scene: PressScene, skin: SkinInstance, active_pa: float, time_s: float) -> Frame:
    """The frame of the current state (call after `mj_forward` with sensors enabled)."""
    m, d, readout = scene.model, scene.data, scene.readout
    depth = readout.depth_m(d)
    contacts = link_contacts(m, d, readout.link_body)
    snap = readout.snapshot(m, d, depth, contacts)
    radius = SENSED_RADIUS_SPACINGS * skin.spacing_m
    total, sensed = contact_forces_n(m, d, contacts, snap.points_m, radius)
    pressure = skin.pressure(depth, sensed)
    active = int(np.count_nonzero(pressure > active_pa))
    return Frame(
        time_s,
        depth,
        pressure,
        active,
        total,
        sensed,
        snap,
        readout,
        scene.geom_label,
        scene.geom_contactor,
    )


def sensed_pressure(skin: SkinInstance, reading: np.ndarray, time_s: float) -> np.ndarray:
    """Pressure (N,) Pa as the robot reads it (`SkinInstance.readout`: the known baseline and
    drift removed, 4 noise sd floor, nominal gain) — what a dataset's readers reproduce."""
    return skin.readout().pressure_pa(reading, time_s)


def label_taxels(
    skin: SkinInstance, frame: Frame, active_pa: float, n_contactors: int = 1
) -> tuple[np.ndarray, np.ndarray]:
    """Per-taxel (class (N,) int64 0..6, contactor index (N,) int64, -1 none) of one frame.

    An active taxel (noise-free pressure above ``active_pa``) takes the class contributing most
    of its pressure through the spread kernel (attributed taxels' own pressure, by class), so
    taxels activated only by spreading inherit their neighbours' class; likewise the contactor
    (of ``n_contactors``) contributing most, where any attributed pressure reaches it.
    """
    base = depth_to_pressure(frame.depth_m, skin.cfg) * (frame.geom >= 0)
    classes = np.arange(7)[:, None]
    parts = np.asarray(skin.spread @ (base[None, :] * (frame.geom_label == classes)).T).T
    reached = (frame.pressure_pa > active_pa) & (parts.sum(axis=0) > 0)
    label = np.where(reached, parts.argmax(axis=0), 0)
    if n_contactors == 1:
        return label.astype(np.int64), np.where(reached, 0, -1).astype(np.int64)
    ids = np.arange(n_contactors)[:, None]
    share = np.asarray(skin.spread @ (base[None, :] * (frame.contactor == ids)).T).T
    return label.astype(np.int64), np.where(reached, share.argmax(axis=0), -1).astype(np.int64)


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
