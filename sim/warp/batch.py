"""One batch of press episodes stepped as the worlds of a batched MuJoCo Warp model.

A `WorldJob` is an episode prepared exactly as `sim.episode.runner.run_episode` prepares it on the C
backend (`sim.episode.press.reset` on its compiled scene, the per-tick
`sim.episode.press.schedule`), plus its converted model (`sim.warp.model.convert`). `run_batch`
steps the jobs of one structure family together: per 10 Hz frame, 10 control ticks (each writes
every world's ctrl row and force limits, then ``n_ctrl`` steps with sensors disabled), then one
``forward`` with sensors on, and each live world's frame is read by `sim.episode.frames.read_frame`
on a view of that world's arrays, so depth, contacts, forces and attribution go through the C
backend's code. Worlds whose plans have fewer frames idle once done; a world that fails is frozen
out of the batch's results.

Checks per frame as on the C backend, where MJWarp exposes them: non-finite state ("nan"), a
taxel deeper than the contactor allows ("too_deep"). MJWarp raises no MuJoCo warnings; its
capacity overflows (contacts, constraint rows) raise `CapacityOverflow` so that the caller
reruns the batch with more room (world results do not depend on the capacity).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import mujoco_warp as mjw
import numpy as np
import warp as wp
from mujoco_warp._src.types import ContactType, DisableBit, OverflowType

from sim.episode import press
from sim.episode.frames import Frame, Frames, read_frame
from sim.episode.runner import CONTROL_DT_S, FRAME_DT_S, EpisodeFailure
from sim.skin.model import SkinInstance
from sim.warp.model import batch_models

# Overflow bits that mean lost contacts or constraint rows (the iteration caps do not: the C
# solver stops there too, silently).
CAPACITY_BITS = int(OverflowType.ALL & ~(OverflowType.ITERATIONS | OverflowType.LS_ITERATIONS))
PER_WORLD_FIELDS = ("actuator_forcerange",)  # written every tick, one row per world


class CapacityOverflow(Exception):
    """A world ran out of contact or constraint rows (`mujoco_warp.OverflowType` names)."""

    def __init__(self, flags: int) -> None:
        super().__init__(str(OverflowType(flags)))
        self.flags = flags


@dataclass
class WorldJob:
    """One prepared episode: its C scene (read-out and labels), its family's device model,
    start state (qpos (nq,)), per-tick schedule, frame counts, the depth that fails it (m) and
    its own model rows (its contactor's, and the reset's press pose; `batch_models`)."""

    scene: press.PressScene
    model: mjw.Model
    qpos: np.ndarray
    sched: press.Schedule
    n_frames: int
    n_hold: int
    max_penetration_m: float
    rows: dict[str, np.ndarray]


@dataclass
class _Contact:
    geom: np.ndarray
    pos: np.ndarray
    efc_address: np.ndarray


@dataclass
class WorldView:
    """The part of one world's state `read_frame` reads, shaped like `mujoco.MjData`'s."""

    sensordata: np.ndarray
    ncon: int
    contact: _Contact
    efc_force: np.ndarray
    geom_xpos: np.ndarray
    geom_xmat: np.ndarray


def _by_tick(rows: list[np.ndarray]) -> np.ndarray:
    """(T, W, ...) C-ordered from per-world (T_w, ...) arrays (a tick's rows contiguous, as a
    device copy wants them); shorter ones repeat their last row."""
    t = max(len(r) for r in rows)
    padded = [np.concatenate([r, np.repeat(r[-1:], t - len(r), axis=0)]) for r in rows]
    return np.ascontiguousarray(np.stack(padded, axis=1))


def run_batch(
    jobs: list[WorldJob],
    skin: SkinInstance,
    active_pa: float,
    device: str,
    nconmax: int,
    njmax: int,
) -> list[Frames | EpisodeFailure]:
    """Step ``jobs`` (one structure family) as worlds; per job its `Frames` or its failure.

    A failure before the end of the hold fails the episode; one after it (a kept sequence's
    release) ends its frames there, as `sim.episode.runner.run_episode` does.
    """
    with wp.ScopedDevice(device):
        m = batch_models(jobs[0].model, [j.rows for j in jobs], device, PER_WORLD_FIELDS)
        d = mjw.make_data(jobs[0].scene.model, nworld=len(jobs), nconmax=nconmax, njmax=njmax)
        d.qpos.assign(np.stack([j.qpos for j in jobs]))
        return _run(m, d, jobs, skin, active_pa)


def _run(m, d, jobs: list[WorldJob], skin: SkinInstance, active_pa: float) -> list:
    ctrl = _by_tick([j.sched.ctrl for j in jobs])
    limits = _by_tick([j.sched.forcerange for j in jobs])
    per_frame = round(FRAME_DT_S / CONTROL_DT_S)
    n_ctrl = max(1, round(CONTROL_DT_S / jobs[0].scene.model.opt.timestep))
    frames: list[list[Frame]] = [[] for _ in jobs]
    out: list[Frames | EpisodeFailure | None] = [None] * len(jobs)
    for k in range(max(j.n_frames for j in jobs)):
        m.opt.disableflags |= DisableBit.SENSOR
        for tick in range(k * per_frame, (k + 1) * per_frame):
            d.ctrl.assign(ctrl[tick])
            m.actuator_forcerange.assign(limits[tick])
            for _ in range(n_ctrl):
                mjw.step(m, d)
        m.opt.disableflags &= ~DisableBit.SENSOR
        mjw.forward(m, d)
        state = _read_state(d)
        for w, job in enumerate(jobs):
            if out[w] is None:
                out[w] = _frame(job, state, w, k, skin, active_pa, frames[w])
        if all(o is not None for o in out):
            break
    return out


def _frame(
    job: WorldJob, state: dict, w: int, k: int, skin: SkinInstance, active_pa: float, got: list
) -> Frames | EpisodeFailure | None:
    """Read and check frame ``k`` of world ``w`` into ``got``; the world's outcome when it ends
    here (its Frames, or the failure), None while it goes on."""
    try:
        got.append(_read_world(job, state, w, (k + 1) * FRAME_DT_S, skin, active_pa))
    except EpisodeFailure as failure:
        return failure if k < job.n_hold else Frames(got, job.n_hold)
    return Frames(got, job.n_hold) if k + 1 == job.n_frames else None


def _read_state(d) -> dict:
    """The arrays of all worlds a frame needs, on the host (one copy each)."""
    nacon = min(int(d.nacon.numpy()[0]), d.naconmax)
    kind = d.contact.type.numpy()[:nacon]
    return {
        "overflow": d.overflow.numpy(),
        "qpos": d.qpos.numpy(),
        "qvel": d.qvel.numpy(),
        "sensordata": d.sensordata.numpy(),
        "efc_force": d.efc.force.numpy(),
        "geom_xpos": d.geom_xpos.numpy(),
        "geom_xmat": d.geom_xmat.numpy(),
        "worldid": np.where(
            kind & int(ContactType.CONSTRAINT), d.contact.worldid.numpy()[:nacon], -1
        ),
        "geom": d.contact.geom.numpy()[:nacon],
        "pos": d.contact.pos.numpy()[:nacon],
        "efc_address": d.contact.efc_address.numpy()[:nacon, 0],
    }


def _read_world(
    job: WorldJob, state: dict, w: int, time_s: float, skin: SkinInstance, active_pa: float
) -> Frame:
    """Frame of world ``w`` (EpisodeFailure "nan" / "too_deep"; CapacityOverflow)."""
    flags = int(state["overflow"][w]) & CAPACITY_BITS
    if flags:
        raise CapacityOverflow(flags)
    if not (np.isfinite(state["qpos"][w]).all() and np.isfinite(state["qvel"][w]).all()):
        raise EpisodeFailure("nan", "non-finite state")
    mine = np.flatnonzero(state["worldid"] == w)  # generation order: same in any batch
    view = WorldView(
        state["sensordata"][w].astype(np.float64),
        len(mine),
        _Contact(
            state["geom"][mine], state["pos"][mine].astype(np.float64), state["efc_address"][mine]
        ),
        state["efc_force"][w].astype(np.float64),
        state["geom_xpos"][w].astype(np.float64),
        state["geom_xmat"][w].reshape(-1, 9).astype(np.float64),
    )
    frame = read_frame(dataclasses.replace(job.scene, data=view), skin, active_pa, time_s)
    if frame.depth_m.max() > job.max_penetration_m:
        deepest, cap = frame.depth_m.max() * 1e3, job.max_penetration_m * 1e3
        raise EpisodeFailure("too_deep", f"{deepest:.2f} mm > {cap:.2f}")
    return frame
