"""Readout against closed forms on a flat plate: contact radius, symmetry, attribution, order."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from scipy.spatial import Delaunay, cKDTree

from sim.episode.scene import Contactor, SkinScene
from sim.skin.geometry import plate_mesh
from sim.skin.model import SkinConfig, SkinInstance
from sim.skin.parts import Part, get_part
from tactile.errors import ConfigError
from tactile.geometry.layout import TaxelLayout

PITCH_M = 8e-3


def hex_part(pitch_m: float = PITCH_M, rings: int = 9) -> Part:
    """A flat hexagonal lattice centred on a taxel at the origin: six-fold symmetric."""
    i, j = np.meshgrid(np.arange(-rings, rings + 1), np.arange(-rings, rings + 1))
    xy = (i.ravel()[:, None] * [1.0, 0.0] + j.ravel()[:, None] * [0.5, np.sqrt(3) / 2]) * pitch_m
    xy = xy[np.linalg.norm(xy, axis=1) < rings * pitch_m * 0.87]
    pos = np.column_stack([xy, np.zeros(len(xy))])
    normals = np.tile([0.0, 0.0, 1.0], (len(pos), 1))
    layout = TaxelLayout(positions_m=pos, normals=normals, name="hex")
    faces = Delaunay(xy).simplices.astype(np.int64)
    return Part("hex", plate_mesh(), layout, faces, xy * 1e3)


def press(scene: SkinScene, name: str, depth_m: float) -> None:
    """Place contactor `name` (started touching the surface) `depth_m` deep, kinematically."""
    scene.data.joint(f"obj_{name}").qpos = depth_m
    scene.forward()


def ball(name: str, radius_m: float, xy: tuple[float, float], label: int = 1) -> Contactor:
    return Contactor(name, "sphere", (radius_m,), (xy[0], xy[1], radius_m), label=label)


def test_sensor_depth_is_the_sphere_penetration() -> None:
    part = get_part("plate")
    centre = part.layout.positions_m[100]
    scene = SkinScene(part, (ball("b", 0.02, tuple(centre[:2])),))
    press(scene, "b", 1.5e-3)
    c = scene.data.geom("obj_b").xpos
    expect = np.maximum(0.02 - np.linalg.norm(part.layout.positions_m - c, axis=1), 0.0)
    np.testing.assert_allclose(scene.taxel_depth_m(), expect, atol=1e-7)


@pytest.mark.parametrize(("radius_m", "depth_m"), [(0.05, 2e-3), (0.02, 1e-3), (0.1, 0.5e-3)])
def test_active_taxels_lie_within_contact_radius(radius_m: float, depth_m: float) -> None:
    part = get_part("plate")
    centre = part.layout.positions_m[150, :2]
    scene = SkinScene(part, (ball("b", radius_m, tuple(centre)),))
    press(scene, "b", depth_m)
    active = scene.read().contactor >= 0
    rho = np.linalg.norm(part.layout.positions_m[:, :2] - centre, axis=1)
    a = np.sqrt(2 * radius_m * depth_m)  # Hertz/Winkler contact radius (small depth)
    np.testing.assert_array_equal(active, rho < np.sqrt(2 * radius_m * depth_m - depth_m**2))
    assert a - PITCH_M <= rho[active].max() <= a


def test_world_positions_keep_vertex_order_on_a_moving_link() -> None:
    part = get_part("end_effector")
    scene = SkinScene(part, hinge=True)
    scene.data.joint("fa_mount").qpos = 0.07
    scene.forward()
    body = scene.data.body("fa_link")
    expect = body.xpos + part.layout.positions_m @ body.xmat.reshape(3, 3).T
    np.testing.assert_allclose(scene.taxel_positions_m(), expect, atol=1e-7)
    assert not np.allclose(scene.taxel_positions_m(), part.layout.positions_m, atol=1e-3)


def test_symmetric_indentation_gives_a_symmetric_frame() -> None:
    part = hex_part()
    scene = SkinScene(part, (ball("b", 0.03, (0.0, 0.0)),))
    press(scene, "b", 2e-3)
    skin = SkinInstance.create(
        part.layout.positions_m,
        SkinConfig(gain_spread=0.0, baseline_spread_counts=0.0, spread_sigma_m=3e-3),
        np.random.default_rng(0),
    )
    pressure = skin.frame(scene.taxel_depth_m(), rng=None).pressure_pa
    assert (pressure > 0).sum() >= 19
    xy = part.layout.positions_m[:, :2]
    tree = cKDTree(xy)
    for angle in np.deg2rad([60.0, 120.0, 180.0]):
        rot = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        dist, idx = tree.query(xy @ rot.T)
        assert dist.max() < 1e-9
        np.testing.assert_allclose(pressure[idx], pressure, rtol=1e-5, atol=1e-3)
    dist, idx = tree.query(xy * [-1.0, 1.0])
    np.testing.assert_allclose(pressure[idx], pressure, rtol=1e-5, atol=1e-3)


def test_attribution_of_two_contactors_on_separate_regions() -> None:
    part = get_part("plate")
    box = Contactor("box", "box", (0.015, 0.015, 0.01), (0.05, 0.04, 0.01), label=7)
    scene = SkinScene(part, (ball("b", 0.03, (-0.05, -0.03), label=3), box))
    press(scene, "b", 2e-3)
    press(scene, "box", 1e-3)
    frame = scene.read()
    xy = part.layout.positions_m[:, :2]
    under_ball = np.linalg.norm(xy - [-0.05, -0.03], axis=1) < np.sqrt(2 * 0.03 * 2e-3 - 4e-6)
    under_box = np.all(np.abs(xy - [0.05, 0.04]) < 0.015, axis=1)
    assert under_ball.sum() > 3 and under_box.sum() > 3
    np.testing.assert_array_equal(frame.contactor, np.select([under_ball, under_box], [0, 1], -1))
    np.testing.assert_array_equal(frame.label, np.select([under_ball, under_box], [3, 7], -1))


def test_attribution_picks_the_deeper_of_overlapping_contactors() -> None:
    part = hex_part()
    scene = SkinScene(part, (ball("a", 0.05, (-0.006, 0.0), 1), ball("b", 0.05, (0.006, 0.0), 2)))
    press(scene, "a", 2.0e-3)
    press(scene, "b", 3.0e-3)
    frame = scene.read()
    pos = part.layout.positions_m
    pen = np.stack(
        [
            r - np.linalg.norm(pos - scene.data.geom(g).xpos, axis=1)
            for g, r in (("obj_a", 0.05), ("obj_b", 0.05))
        ]
    )
    touched = pen.max(axis=0) > 0
    overlap = (pen > 0).all(axis=0)
    assert overlap.sum() >= 2
    np.testing.assert_array_equal(frame.contactor[touched], np.argmax(pen, axis=0)[touched])
    np.testing.assert_allclose(frame.depth_m, np.maximum(pen.max(axis=0), 0), atol=1e-7)


def test_mesh_contactors_are_rejected_by_attribution() -> None:
    part = get_part("plate")
    scene = SkinScene(part)
    from sim.skin.readout import TaxelReadout

    with pytest.raises(ConfigError, match="not a supported primitive"):
        TaxelReadout(scene.model, "fa_tactile", "fa_skin", ["fa_link_collision"])


def test_a_mocap_contactor_on_a_fixed_link_makes_no_contact() -> None:
    """MuJoCo skips contacts between two bodies without degrees of freedom (experiment)."""
    part = get_part("plate")
    spec = SkinScene(part).spec
    body = spec.worldbody.add_body(name="obj_mocap", pos=[0, 0, 0.009], mocap=True)
    body.add_geom(name="obj_mocap", type=mujoco.mjtGeom.mjGEOM_SPHERE, size=[0.01, 0, 0])
    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    assert data.ncon == 0


def test_mujoco_box_depth_is_exact_at_the_centre_and_larger_near_edges() -> None:
    """MuJoCo's box distance inside the box is not the exact one (experiment, mujoco 4.0.0): it
    equals the penetration under the box centre and exceeds it towards the edges (√3× at a
    corner). Attribution uses the exact distance; depths from the sensor keep MuJoCo's."""
    part = hex_part()
    scene = SkinScene(part, (Contactor("box", "box", (0.012, 0.012, 0.01), (0.0, 0.0, 0.01)),))
    press(scene, "box", 1e-3)
    depth = scene.taxel_depth_m()
    xy = part.layout.positions_m[:, :2]
    inside = np.all(np.abs(xy) < 0.012, axis=1)
    centre = int(np.argmin(np.linalg.norm(xy, axis=1)))
    assert depth[centre] == pytest.approx(1e-3, rel=0.05)
    assert np.all(depth[inside] >= 1e-3 * 0.999) and depth[inside].max() > 1.02e-3
    np.testing.assert_array_equal(scene.read().contactor >= 0, inside)
