"""Body-part contactors and the non-hand mixture: compile and press on the forearm, human-size
ranges, determinism, primitives, soft tissue, press plans, mixture fractions."""

from __future__ import annotations

import json
from collections import Counter

import mujoco
import numpy as np
import pytest

from sim import press
from sim.bodyparts import BODY_KINDS, BODY_MODES, body_press, build_body_part, plan_body_press
from sim.contactors import PressPlan
from sim.nonhand import (
    BROAD_OBJECTS,
    BROAD_SHARE,
    OBJECT_FRACTION,
    instance_id_for,
    mixture,
    sample_nonhand,
)
from sim.objects import HARD_NEGATIVES
from sim.parts import get_part
from tactile.errors import ConfigError

BODY_SHAPES = {int(mujoco.mjtGeom.mjGEOM_CAPSULE), int(mujoco.mjtGeom.mjGEOM_ELLIPSOID)}


def press_for(contactor, plan: PressPlan, seconds: float = 1.0):
    """Press on the forearm's middle band for ``seconds``; (max depth (N,) m, warnings)."""
    part = get_part("forearm")
    scene = press.build_press_scene(part, contactor, 0.002)
    k = int(np.argmin(np.linalg.norm(part.flat_mm - np.median(part.flat_mm, axis=0), axis=1)))
    z = part.layout.normals[k]
    x = np.array([0.0, 0.0, 1.0]) - z[2] * z
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, np.column_stack([x / np.linalg.norm(x), np.cross(z, x), z]).ravel())
    press.reset(scene, plan, part.layout.positions_m[k], quat / np.linalg.norm(quat))
    deepest = np.zeros(part.n_taxels)
    for _ in range(round(seconds / 0.01)):
        press.apply_controls(scene, plan, scene.data.time)
        mujoco.mj_step(scene.model, scene.data, nstep=5)
        deepest = np.maximum(deepest, scene.readout.depth_m(scene.data))
    return deepest, {i: w.number for i, w in enumerate(scene.data.warning) if w.number}


@pytest.mark.parametrize("kind", BODY_KINDS)
def test_body_part_presses_forearm_without_warnings(kind: str) -> None:
    c = build_body_part(kind, None, 0)
    depth, warnings = press_for(c, PressPlan(force_n=40.0, durations_s=(0.2, 0.3, 0.5, 0.0)))
    assert not warnings
    assert 0 < depth.max() < c.max_penetration_m


@pytest.mark.parametrize("kind", BODY_KINDS)
def test_capsules_and_ellipsoids_of_soft_tissue(kind: str) -> None:
    c = build_body_part(kind, None, 4)
    model = c.spec.compile()
    assert all(int(t) in BODY_SHAPES for t in model.geom_type)
    assert sorted(model.geom(i).name for i in range(model.ngeom)) == sorted(c.geom_labels)
    assert set(c.geom_labels.values()) == {0} and c.kind == "body" and c.subject_id == -1
    assert all(n.startswith("bp_") for n in c.geom_labels)
    widths = c.description["stiffness"]["compliance_depth_m"].values()
    assert all(0.006 <= w <= 0.025 for w in widths)
    assert 1.0 <= c.description["mass_kg"] <= 4.5
    json.dumps(c.description)


@pytest.mark.parametrize("kind", BODY_KINDS)
def test_instances_are_deterministic(kind: str) -> None:
    a, b = build_body_part(kind, None, 11), build_body_part(kind, np.random.default_rng(5), 11)
    assert a.spec.to_xml() == b.spec.to_xml() and a.description == b.description
    assert build_body_part(kind, None, 12).description != a.description


# Anthropometric ranges (ANSUR II, Gordon et al. 2014; see sim/bodyparts.py), metres.
RANGES = {
    "forearm": [
        ("half_width", 0.038, 0.050),
        ("wrist_radius", 0.022, 0.030),
        ("length", 0.24, 0.29),
    ],
    "upper_arm": [("radius", 0.040, 0.058), ("length", 0.28, 0.36)],
    "elbow": [("olecranon_half_width", 0.022, 0.028), ("flexion", np.deg2rad(60), np.deg2rad(120))],
    "shoulder": [("deltoid_x", 0.055, 0.07), ("arm_radius", 0.040, 0.055)],
    "chest": [("half_breadth", 0.135, 0.19), ("half_depth", 0.105, 0.15)],
    "back": [("half_breadth", 0.135, 0.19), ("scapula_proud", 0.01, 0.02)],
    "knee": [("patella_half_width", 0.0225, 0.0275), ("thigh_radius", 0.07, 0.10)],
    "head": [
        ("half_breadth", 0.07, 0.0825),
        ("half_length", 0.09, 0.105),
        ("half_height", 0.105, 0.12),
    ],
}


@pytest.mark.parametrize("kind", BODY_KINDS)
def test_dimensions_within_anthropometric_ranges(kind: str) -> None:
    for i in range(30):
        dims = build_body_part(kind, None, i).description["dimensions_m"]
        for key, lo, hi in RANGES[kind]:
            assert lo - 1e-5 <= dims[key] <= hi + 1e-5, (key, dims[key])


def test_body_press_plans_within_kind_forces() -> None:
    rng = np.random.default_rng(1)
    for i in range(160):
        c = build_body_part(BODY_KINDS[i % len(BODY_KINDS)], None, i)
        mode, plan = body_press(c, rng)
        (lo, hi), modes = BODY_MODES[c.name]
        assert mode in modes and lo - 1e-9 <= plan.force_n <= hi + 1e-9
        assert plan.action == -1 and plan.site_uv is None
    assert isinstance(plan_body_press(c, rng), PressPlan)


def test_unknown_body_part() -> None:
    with pytest.raises(ConfigError, match="known kinds: forearm"):
        build_body_part("tail", None, 0)


def test_mixture_fractions() -> None:
    table = mixture()
    assert sum(table.values()) == pytest.approx(1.0)
    assert sum(p for (k, _), p in table.items() if k == "object") == pytest.approx(OBJECT_FRACTION)
    hard = sum(table[("object", n)] for n in HARD_NEGATIVES)
    assert hard == pytest.approx(0.30 * OBJECT_FRACTION)
    broad = sum(table[("object", n)] for n in BROAD_OBJECTS)
    assert broad == pytest.approx(BROAD_SHARE * OBJECT_FRACTION)


def test_thick_soft_tissue_sinks_centimetres_under_a_lean() -> None:
    """A chest leaning with 60 N sinks more than 5 mm into the link (measured 6.4 mm), within its
    allowance: the print of thick soft tissue is broad."""
    c = build_body_part("chest", None, 1)
    depth, warnings = press_for(c, PressPlan(force_n=60.0, durations_s=(0.2, 0.3, 0.5, 0.0)))
    assert not warnings
    assert 0.005 < depth.max() < c.max_penetration_m


def test_sample_nonhand_draws_the_mixture_and_pools() -> None:
    rng = np.random.default_rng(0)
    draws = [sample_nonhand(rng, instances_per_kind=3) for _ in range(400)]
    kinds = Counter(c.kind for c, _ in draws)
    assert abs(kinds["object"] / 400 - OBJECT_FRACTION) < 0.07
    ids = {(c.name, c.instance_id) for c, _ in draws}
    assert len({i for _, i in ids}) == len(ids)  # global ids are unique across types
    assert all("press" in c.description for c, _ in draws)
    first = {c.name: instance_id_for(c.kind, c.name, 0) for c, _ in draws}
    assert all(first[c.name] <= c.instance_id < first[c.name] + 3 for c, _ in draws)
