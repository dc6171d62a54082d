"""Taxel readout from MuJoCo: depth per taxel (layout order), world taxel positions, who pressed.

MuJoCo's ``tactile`` sensor on a mesh geom reports, per mesh vertex, the deepest penetration of any
geom in contact with the sensor's weld body (``-SDF`` clipped at 0; primitives are evaluated
analytically, meshes only with ``needsdf``). It keeps only the deepest geom, so attribution — which
contactor pressed each taxel — is recomputed here from exact signed distances of the contactor
primitives at the taxel positions (verified by experiment: the sensor equals these distances for
spheres, capsules, cylinders; MuJoCo's box distance inside the box overestimates near the edges,
up to √3× at a corner, so a box's depths differ while its attribution does not).

MuJoCo recentres (and rotates) meshes; vertex order is kept. World taxel positions are therefore
``geom_xpos + geom_xmat @ mesh_vert`` from the compiled model. Other behaviour checked by
experiment (mujoco 4.0.0): vertices on no face are still read; the sensor's ``cutoff`` clips the
depth at that value; a geom penetrating the taxels but not in contact with the sensor's body is
ignored; a mocap contactor against a fixed link makes no contact at all.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from tactile.errors import ConfigError

GT = mujoco.mjtGeom


def _sphere(q: np.ndarray, size: np.ndarray) -> np.ndarray:
    return np.linalg.norm(q, axis=-1) - size[0]


def _capsule(q: np.ndarray, size: np.ndarray) -> np.ndarray:
    axial = np.clip(q[..., 2], -size[1], size[1])
    q = q.copy()
    q[..., 2] -= axial
    return np.linalg.norm(q, axis=-1) - size[0]


def _cylinder(q: np.ndarray, size: np.ndarray) -> np.ndarray:
    dr = np.hypot(q[..., 0], q[..., 1]) - size[0]
    dz = np.abs(q[..., 2]) - size[1]
    inside = np.minimum(np.maximum(dr, dz), 0.0)
    return inside + np.hypot(np.maximum(dr, 0.0), np.maximum(dz, 0.0))


def _box(q: np.ndarray, size: np.ndarray) -> np.ndarray:
    d = np.abs(q) - size[:3]
    outside = np.linalg.norm(np.maximum(d, 0.0), axis=-1)
    return outside + np.minimum(d.max(axis=-1), 0.0)


def _ellipsoid(q: np.ndarray, size: np.ndarray) -> np.ndarray:
    """Approximate (first-order) ellipsoid distance: exact on the surface and on the axes."""
    k0 = np.linalg.norm(q / size[:3], axis=-1)
    k1 = np.linalg.norm(q / size[:3] ** 2, axis=-1)
    return k0 * (k0 - 1.0) / np.maximum(k1, 1e-12)


SDF: dict[int, Callable[[np.ndarray, np.ndarray], np.ndarray]] = {
    int(GT.mjGEOM_SPHERE): _sphere,
    int(GT.mjGEOM_CAPSULE): _capsule,
    int(GT.mjGEOM_CYLINDER): _cylinder,
    int(GT.mjGEOM_BOX): _box,
    int(GT.mjGEOM_ELLIPSOID): _ellipsoid,
}


def signed_distance(
    geom_type: int, size: np.ndarray, xpos: np.ndarray, xmat: np.ndarray, points_m: np.ndarray
) -> np.ndarray:
    """Signed distance (K,) m of world points (K, 3) m to a primitive geom (negative inside).

    xpos : (3,) geom position, m; xmat : (9,) or (3, 3) geom orientation.
    """
    local = (points_m - xpos) @ np.reshape(xmat, (3, 3))
    return SDF[int(geom_type)](local, np.asarray(size))


def mesh_vertices_local(model: mujoco.MjModel, geom_id: int) -> np.ndarray:
    """Vertices (V, 3) float64, m, of a mesh geom in the geom frame (MuJoCo's recentred copy)."""
    mesh = int(model.geom_dataid[geom_id])
    adr, num = int(model.mesh_vertadr[mesh]), int(model.mesh_vertnum[mesh])
    return np.array(model.mesh_vert[adr : adr + num], dtype=np.float64)


def world_points(local_m: np.ndarray, xpos: np.ndarray, xmat: np.ndarray) -> np.ndarray:
    """Points (K, 3) from a frame to world: xpos + R @ p. xmat (9,) or (3, 3)."""
    return xpos + local_m @ np.reshape(xmat, (3, 3)).T


@dataclass(frozen=True)
class ReadoutFrame:
    """Per-taxel readout of one simulator state.

    depth_m : (N,) float, m — sensor penetration depth, layout order.
    contactor : (N,) int64 — index into the readout's contactors of the deepest one, -1 none.
    label : (N,) int64 — that contactor's label, `background` where none.
    """

    depth_m: np.ndarray
    contactor: np.ndarray
    label: np.ndarray


@dataclass(frozen=True)
class LinkContacts:
    """The contacts between the link and anything else: ``index`` (C,) int64 into
    `mjData.contact`, ``other_geom`` (C,) int64 the geom on the other side."""

    index: np.ndarray
    other_geom: np.ndarray


def link_contacts(model: mujoco.MjModel, data: mujoco.MjData, link_body: int) -> LinkContacts:
    """The contacts with exactly one side on the weld body ``link_body``."""
    pairs = np.asarray(data.contact.geom[: data.ncon]).reshape(-1, 2)
    on_link = model.body_weldid[model.geom_bodyid[pairs]] == link_body
    index = np.flatnonzero(on_link[:, 0] != on_link[:, 1])
    other = np.where(on_link[index, 0], pairs[index, 1], pairs[index, 0])
    return LinkContacts(index, other)


@dataclass(frozen=True)
class ContactSnapshot:
    """The state attribution needs, kept per frame so that only the selected frame is attributed.

    active : (K,) int64 pressed taxels; points_m : (K, 3) their world positions, m;
    candidates : (C,) int64 readout contactors touching the link; xpos (C, 3) m, xmat (C, 9):
    their geom poses.
    """

    active: np.ndarray
    points_m: np.ndarray
    candidates: np.ndarray
    xpos: np.ndarray
    xmat: np.ndarray


class TaxelReadout:
    """Reads depth, taxel positions and attribution for one sensor mesh geom of a compiled model.

    contactors : geom names that may press the skin (primitives); labels : one int per contactor.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        sensor: str,
        skin_geom: str,
        contactors: Sequence[str],
        labels: Sequence[int] | None = None,
        background: int = -1,
    ) -> None:
        self.skin_geom = model.geom(skin_geom).id
        self.local_m = mesh_vertices_local(model, self.skin_geom)
        self.n_taxels = self.local_m.shape[0]
        sens = model.sensor(sensor)
        if int(sens.dim[0]) != 3 * self.n_taxels:
            raise ConfigError(f"sensor {sensor!r} has dim {sens.dim[0]}, not 3 x {self.n_taxels}")
        self.adr = int(sens.adr[0])
        self.geoms = np.array([model.geom(g).id for g in contactors], dtype=np.int64)
        self._check_types(model, contactors)
        lab = np.arange(len(contactors)) if labels is None else np.asarray(labels, np.int64)
        self.labels = np.append(lab, background).astype(np.int64)  # index -1 -> background
        self.link_body = int(model.body_weldid[model.geom_bodyid[self.skin_geom]])
        self._types = model.geom_type[self.geoms].copy()
        self._sizes = model.geom_size[self.geoms].copy()

    def _check_types(self, model: mujoco.MjModel, names: Sequence[str]) -> None:
        for gid, name in zip(self.geoms, names, strict=True):
            if int(model.geom_type[gid]) not in SDF:
                known = ", ".join(GT(t).name.removeprefix("mjGEOM_").lower() for t in SDF)
                raise ConfigError(f"contactor geom {name!r} is not a supported primitive ({known})")

    def depth_m(self, data: mujoco.MjData) -> np.ndarray:
        """Penetration depth (N,) m at each taxel, layout order (a copy)."""
        return np.array(data.sensordata[self.adr : self.adr + self.n_taxels])

    def positions_m(self, data: mujoco.MjData, idx: np.ndarray | None = None) -> np.ndarray:
        """World taxel positions (N, 3) m (or (K, 3) for taxel indices idx)."""
        local = self.local_m if idx is None else self.local_m[idx]
        return world_points(local, data.geom_xpos[self.skin_geom], data.geom_xmat[self.skin_geom])

    def touching(
        self, model: mujoco.MjModel, data: mujoco.MjData, contacts: LinkContacts | None = None
    ) -> np.ndarray:
        """(K,) bool: which contactors are in contact with the sensor's weld body."""
        contacts = contacts or link_contacts(model, data, self.link_body)
        return np.isin(self.geoms, contacts.other_geom)

    def snapshot(
        self,
        model: mujoco.MjModel,
        data: mujoco.MjData,
        depth_m: np.ndarray,
        contacts: LinkContacts | None = None,
    ) -> ContactSnapshot:
        """What attribution needs of the current state, copied: the pressed taxels (depth > 0),
        their world positions and the poses of the contactors touching the link."""
        active = np.flatnonzero(depth_m > 0)
        cand = np.flatnonzero(self.touching(model, data, contacts)) if active.size else active
        g = self.geoms[cand]
        return ContactSnapshot(
            active,
            self.positions_m(data, active),
            cand,
            np.array(data.geom_xpos[g]),
            np.array(data.geom_xmat[g]),
        )

    def attribute(self, snap: ContactSnapshot) -> np.ndarray:
        """(N,) int64: per taxel, the index of the contactor penetrating it deepest, -1 none."""
        who = np.full(self.n_taxels, -1, dtype=np.int64)
        if not (snap.active.size and snap.candidates.size):
            return who
        pen = np.empty((len(snap.candidates), len(snap.active)))
        for row, c in enumerate(snap.candidates):
            pen[row] = -signed_distance(
                self._types[c], self._sizes[c], snap.xpos[row], snap.xmat[row], snap.points_m
            )
        best = np.argmax(pen, axis=0)
        deepest = pen[best, np.arange(snap.active.size)]
        who[snap.active] = np.where(deepest > 0, snap.candidates[best], -1)
        return who

    def read(self, model: mujoco.MjModel, data: mujoco.MjData) -> ReadoutFrame:
        """Depth and attribution for the current state (after mj_forward or mj_step)."""
        depth = self.depth_m(data)
        who = self.attribute(self.snapshot(model, data, depth))
        return ReadoutFrame(depth, who, self.labels[who])
