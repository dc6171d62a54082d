"""Episodes prepared for the warp backend: the C backend's start, then the world's model rows.

`JobMaker.prepare` starts an episode with `sim.episode.runner.start_episode` — the same site draw,
reset and per-tick schedule as `sim.episode.runner.run_episode` — and packs it as a
`sim.warp.batch.WorldJob`. A contactor's device model (`sim.warp.model.convert`, about 60 ms)
is made once per contactor key: its structure family's digest and its batchable rows are kept,
the model itself only as its family's reference. An episode differs from its contactor's model
only where `sim.episode.press.reset` writes the compiled model (the ``press`` body's pose, and the
force limits the schedule rewrites every tick), which the job carries as rows of its own.

Capacities (`capacity`): a contactor's contacts per world are bounded from its collision geoms,
measured on the C backend (a hand's 45 geoms make at most 49 contacts; a box pressed flat on the
forearm's mesh 46) and doubled; constraint rows are the contact's cone rows (elliptic: condim)
plus one per limited joint.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import mujoco
import mujoco_warp as mjw
import numpy as np

from sim.contactors.spec import ContactorSpec, PressPlan
from sim.episode.runner import EpisodeContext, as_list, contactor_key, start_episode
from sim.warp.batch import WorldJob
from sim.warp.model import convert, structure_digest, world_rows

CONTACTS_PER_GEOM = 2  # count: a hand makes <= 49 contacts from 45 geoms on the C backend
FACE_CONTACTS = 48  # count: a flat face on the link mesh (a box pressed flat: 46)
SAFETY = 2.0  # margin on both estimates (an overflow reruns the batch with twice the room)
JOB_ROWS = ("body_pos", "body_quat", "actuator_forcerange")  # written by `sim.episode.press.reset`


@dataclass(frozen=True)
class KeyModel:
    """A contactor's structure family, capacities (counts) and own device-model rows (20 KB for
    a hand: kept for every contactor a worker meets, so each is converted once)."""

    digest: str
    nconmax: int
    njmax: int
    rows: dict[str, np.ndarray]


def capacity(model: mujoco.MjModel, n_contactor_geoms: int) -> tuple[int, int]:
    """(contacts, constraint rows) per world for a press scene with that many contactor
    collision geoms, with the `SAFETY` margin; multiples of 16."""
    contacts = SAFETY * (CONTACTS_PER_GEOM * n_contactor_geoms + FACE_CONTACTS)
    rows = contacts * int(model.geom_condim.max()) + int(np.count_nonzero(model.jnt_limited))
    return _round16(contacts), _round16(rows)


def _round16(x: float) -> int:
    return int(-(-x // 16) * 16)


class JobMaker:
    """Prepares `WorldJob`s on one device for one `EpisodeContext` (a worker's): one device
    model per structure family, the rows of every contactor key met (LRU, ``cache_size``)."""

    def __init__(self, ctx: EpisodeContext, device: str, cache_size: int = 4096) -> None:
        self.ctx, self.device, self.cache_size = ctx, device, cache_size
        self._keys: OrderedDict[str, KeyModel] = OrderedDict()
        self._families: dict[str, mjw.Model] = {}

    def prepare(
        self,
        contactor: ContactorSpec | list[ContactorSpec],
        plan: PressPlan | list[PressPlan],
        rng: np.random.Generator,
        keep_release: bool = False,
    ) -> tuple[WorldJob, KeyModel]:
        """The job of ``plan`` on ``contactor`` (or of several pressing at once; ``rng`` after
        the maker's draws, as on the C backend) and its contactor key's `KeyModel`."""
        start = start_episode(self.ctx, contactor, plan, rng, keep_release)
        m = start.scene.model
        km = self._key_model(contactor, start.scene)
        own = {name: np.array(getattr(m, name)) for name in JOB_ROWS}
        job = WorldJob(
            start.scene,
            self._families[km.digest],
            np.array(start.scene.data.qpos),
            start.sched,
            start.n_frames,
            start.n_hold,
            max(c.max_penetration_m for c in as_list(contactor)),
            km.rows | own,
        )
        return job, km

    def _key_model(self, contactor, scene) -> KeyModel:
        key = " + ".join(contactor_key(c) for c in as_list(contactor))  # as `EpisodeContext`
        if key in self._keys:
            self._keys.move_to_end(key)
            return self._keys[key]
        wm = convert(scene.model, self.device)
        digest = structure_digest(scene.model, wm)
        self._families.setdefault(digest, wm)
        rows = {n: r for n, r in world_rows(wm).items() if n not in JOB_ROWS}
        km = KeyModel(digest, *capacity(scene.model, len(scene.readout.geoms)), rows)
        self._keys[key] = km
        if len(self._keys) > self.cache_size:
            self._keys.popitem(last=False)
        return km
