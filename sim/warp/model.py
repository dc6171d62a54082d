"""Batched MuJoCo Warp models: many press scenes as the worlds of one device model.

MJWarp batches a model field per world when its array spec starts with ``*`` (body poses,
masses and inertias, geom sizes and poses, joint axes, actuator gains and force limits, ...).
Two compiled press scenes whose *other* fields are equal — the same kinematic tree, geom types,
meshes and options — therefore run as worlds of one model that carries each world's own values
of the batchable fields: every hand of a dataset (any subject, left or right) is one family,
every instance of an object kind another. `structure_digest` names the family of a converted
model; `batch_models` stacks the worlds' own rows (`world_rows`) onto one model of the family,
field by field, so world ``w`` sees exactly the arrays ``put_model`` makes of its own scene.

Fields read only by sleep/islands (`SLEEP_ONLY`) are left out of the digest when sleep is off,
as it is in every press scene: they are unbatched in MJWarp and differ between hands.
"""

from __future__ import annotations

import copy
import dataclasses
import hashlib
from collections.abc import Mapping, Sequence

import mujoco
import mujoco_warp as mjw
import numpy as np
import warp as wp
from mujoco_warp._src import types as mjw_types
from mujoco_warp._src import warp_util

# Unbatched Model fields used only by sleeping (sleep.py weights velocities by dof_length).
SLEEP_ONLY = frozenset({"dof_length"})


def batchable_fields() -> frozenset[str]:
    """Names of the `mujoco_warp.Model` array fields that may hold one value per world."""
    return frozenset(
        f.name
        for f in dataclasses.fields(mjw_types.Model)
        if warp_util.is_array_spec(f.type) and getattr(f.type, "shape", ())[:1] == ("*",)
    )


BATCHABLE = batchable_fields()


def convert(model: mujoco.MjModel, device: str) -> mjw.Model:
    """``mjw.put_model`` of one compiled scene on ``device`` (overflow warnings off: the
    runner reads the overflow flags itself)."""
    with wp.ScopedDevice(device):
        wm = mjw.put_model(model)
    wm.opt.warn_overflow = 0
    return wm


def _sleep_on(model: mujoco.MjModel) -> bool:
    return bool(model.opt.enableflags & mujoco.mjtEnableBit.mjENBL_SLEEP)


def structure_digest(model: mujoco.MjModel, wm: mjw.Model) -> str:
    """sha256 prefix of every field of ``wm`` that cannot differ between worlds: two scenes
    with the same digest run as worlds of one batched model (`batch_models`)."""
    skip = BATCHABLE | (frozenset() if _sleep_on(model) else SLEEP_ONLY)
    h = hashlib.sha256()
    for f in dataclasses.fields(wm):
        if f.name not in skip:
            h.update(f.name.encode() + b"=")
            _feed(h, getattr(wm, f.name))
    return h.hexdigest()[:16]


def _feed(h, value: object) -> None:
    """Hash ``value``: arrays by dtype, shape and bytes; containers and dataclasses recursively;
    scalars and enums by repr (a callback function by its qualified name)."""
    if isinstance(value, wp.array):
        a = value.numpy()
        h.update(f"{a.dtype}{a.shape}".encode() + a.tobytes())
    elif dataclasses.is_dataclass(value) and not isinstance(value, type):
        for f in dataclasses.fields(value):
            h.update(f.name.encode() + b"=")
            _feed(h, getattr(value, f.name))
    elif isinstance(value, list | tuple):
        h.update(b"(")
        for v in value:
            _feed(h, v)
        h.update(b")")
    elif isinstance(value, dict):
        for k in sorted(value, key=repr):
            h.update(repr(k).encode())
            _feed(h, value[k])
    elif callable(value):
        h.update(getattr(value, "__qualname__", repr(value)).encode())
    else:
        h.update(repr(value).encode() + b";")


def world_rows(wm: mjw.Model) -> dict[str, np.ndarray]:
    """The batchable fields of a converted (unbatched) model, as host arrays of one world."""
    return {n: getattr(wm, n).numpy()[0] for n in BATCHABLE if getattr(wm, n) is not None}


def batch_models(
    reference: mjw.Model,
    rows: Sequence[Mapping[str, np.ndarray]],
    device: str,
    per_world: Sequence[str] = (),
) -> mjw.Model:
    """One model of ``len(rows)`` worlds: ``reference``'s structure (any model of the family,
    `structure_digest`) with world ``w``'s batchable fields from ``rows[w]`` (`world_rows` of its
    own model, perhaps updated), ``reference``'s where ``rows[w]`` has none.

    Fields equal in every world keep MJWarp's shared leading dimension of 1 unless named in
    ``per_world`` (fields the caller rewrites per world while stepping); the others get one row
    per world. ``reference`` is copied (shallow), not changed.
    """
    out = copy.copy(reference)
    with wp.ScopedDevice(device):
        for name in sorted(BATCHABLE):
            first = getattr(reference, name)
            if first is None or first.shape[0] != 1:
                continue
            own = first.numpy()[0]
            values = [r.get(name, own) for r in rows]
            same = all(np.array_equal(values[0], v) for v in values[1:])
            if same and name not in per_world and np.array_equal(values[0], own):
                continue
            stacked = wp.array(np.stack(values), dtype=first.dtype)
            stacked._is_batched = True
            setattr(out, name, stacked)
    return out
