"""Parts: forearm proportions and map size, module tiling, registry, custom part on Baxter W0."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh
from scipy.ndimage import distance_transform_edt
from scipy.spatial import cKDTree

from sim.skin.geometry import ForearmShape, forearm_mesh, rounded_box_mesh
from sim.skin.link_mesh import MeshRepaired
from sim.skin.parts import SKIN_PITCH_MM, W0_REGION, W0_TILING, custom_part, get_part
from sim.skin.tiling import Tiling, closest_on_mesh, module_pads_mm, polar_contour
from tactile.errors import ConfigError
from tactile.figures.maps import coverage_mask
from tactile.geometry.flatten import flatten
from tactile.geometry.surface import triangulate
from tactile.images.tactile_map import TactileMap

PAPER_MAP_MM = (247.0, 362.0)  # Albini & Cannata (2020): Baxter forearm map, height x width
PALM_MM = (85.0, 95.0)  # adult palm footprint, width x length
# Per forearm skin: (largest uncovered disc radius, mm; 10th percentile of a palm's covered
# fraction). Measured: forearm 23 mm / 0.73, forearm_8mm 47 mm / 0.33 (old three bands: 0.19).
COVERAGE_BOUNDS = {"forearm": (30.0, 0.65), "forearm_8mm": (50.0, 0.28)}


@pytest.fixture(scope="module", params=sorted(COVERAGE_BOUNDS))
def forearm_map(request) -> tuple[str, TactileMap]:
    return request.param, TactileMap.build(get_part(request.param).layout, step_mm=1.0)


def palm_coverage(tmap: TactileMap, n: int = 1000, seed: int = 0) -> np.ndarray:
    """Covered fraction (n,) of palm rectangles at random centres/angles in the map's box."""
    mask = coverage_mask(tmap)
    rng = np.random.default_rng(seed)
    lo, hi = tmap.vertex_uv_mm.min(axis=0), tmap.vertex_uv_mm.max(axis=0)
    g = np.stack(np.meshgrid(*[np.linspace(-s / 2, s / 2, 20) for s in PALM_MM]), -1)
    angle = rng.uniform(0, np.pi, n)
    rot = np.stack([np.cos(angle), -np.sin(angle), np.sin(angle), np.cos(angle)], -1)
    uv = np.einsum("nij,kj->nki", rot.reshape(n, 2, 2), g.reshape(-1, 2))
    uv += rng.uniform(lo, hi, (n, 1, 2))
    inside = np.all((uv >= lo) & (uv <= hi), axis=2)
    (h, w), step = tmap.shape, tmap.step_mm
    col = np.clip(((uv[..., 0] - tmap.origin_mm[0]) / step).astype(int), 0, w - 1)
    row = np.clip(((tmap.origin_mm[1] - uv[..., 1]) / step).astype(int), 0, h - 1)
    return (mask[row, col] & inside).sum(axis=1) / np.maximum(inside.sum(axis=1), 1)


def test_forearm_has_the_proportions_of_baxter_w0(shared_data) -> None:
    w0 = trimesh.load(shared_data / "baxter" / "upper_forearm_W0.STL")
    ours = forearm_mesh()
    assert ours.is_watertight and ours.is_convex
    np.testing.assert_allclose(np.sort(ours.extents), np.sort(w0.extents), rtol=0.10)


def test_forearm_map_is_247_by_362_mm_with_768_taxels(forearm_map) -> None:
    name, forearm_map = forearm_map
    part = get_part(name)
    assert part.n_taxels == 768
    assert len(np.unique(part.layout.module_ids)) == 64
    extent = np.ptp(forearm_map.vertex_uv_mm, axis=0)  # (u, v) = (width, height)
    np.testing.assert_allclose(extent[::-1], PAPER_MAP_MM, rtol=0.10)
    assert forearm_map.distortion.summary()["n_flipped"] == 0


def test_forearm_skin_is_one_patch_with_scattered_holes(forearm_map) -> None:
    name, forearm_map = forearm_map
    hole_radius_max_mm, palm_p10_min = COVERAGE_BOUNDS[name]
    layout = get_part(name).layout
    mesh = triangulate(layout.positions_m, layout.normals)
    assert flatten(layout.positions_m, mesh).n_patches == 1 and len(mesh.isolated) == 0
    hole_radius_mm = distance_transform_edt(~coverage_mask(forearm_map)).max()
    assert hole_radius_mm < hole_radius_max_mm
    covered = palm_coverage(forearm_map)
    assert np.percentile(covered, 10) > palm_p10_min


def test_pads_are_scaled_to_the_pitch_and_lie_on_the_surface() -> None:
    tactile_pads = module_pads_mm(8.0)[[0, 1, 2, 3, 4, 5, 7, 8, 9, 11]]  # 6 and 10 are thermal
    d, _ = cKDTree(tactile_pads).query(tactile_pads, 2)
    np.testing.assert_allclose(d[:, 1], 8.0, rtol=0.01)
    part = get_part("forearm")
    pos = part.layout.positions_m
    closest, _ = closest_on_mesh(part.link, pos)
    assert np.linalg.norm(closest - pos, axis=1).max() < 1e-4  # on the link surface
    radial = pos - np.column_stack([np.zeros((len(pos), 2)), pos[:, 2]])
    assert np.all(np.sum(radial * part.layout.normals, axis=1) > 0)  # outward
    pad = part.layout.channel_ids % 12  # the 10 tactile pads of one module keep the pad pitch
    module = (part.layout.module_ids == 0) & (pad != 6) & (pad != 10)
    d, _ = cKDTree(pos[module]).query(pos[module], 2)
    np.testing.assert_allclose(np.median(d[:, 1]) * 1e3, SKIN_PITCH_MM, rtol=0.03)


def test_module_ids_and_channels() -> None:
    layout = get_part("end_effector").layout
    np.testing.assert_array_equal(layout.channel_ids, np.arange(layout.n_taxels))
    np.testing.assert_array_equal(layout.module_ids, np.arange(layout.n_taxels) // 12)


def test_polar_contour_of_a_square() -> None:
    box = rounded_box_mesh((0.1, 0.1, 0.1), 1e-3, subdivisions=1)
    lines = trimesh.intersections.mesh_multiplane(box, [0, 0, 0], [0, 0, 1], [0.0])[0][0]
    theta, r = polar_contour(np.asarray(lines), 8)
    np.testing.assert_allclose(r[theta == 0.0], 0.05, atol=1e-6)  # translation-free plane frame


def test_unknown_part_lists_the_known_ones() -> None:
    known = (
        "forearm_paper, forearm, forearm_8mm, forearm_x2, forearm_x3, forearm_x4, end_effector, "
        "plate"
    )
    with pytest.raises(KeyError, match=f"known parts: {known}"):
        get_part("foream")


def test_bad_tiling_and_region_raise_config_errors() -> None:
    with pytest.raises(ConfigError, match="keep"):
        Tiling(2, 3, 20.0, 30.0, keep=("XX",)).flat()
    wide = Tiling(2, 40, 22.0, 35.0)
    with pytest.raises(ConfigError, match="use fewer modules"):
        custom_mesh_part(wide)


def custom_mesh_part(tiling: Tiling):
    from sim.skin.parts import FOREARM_REGION, make_part

    return make_part("wide", forearm_mesh(ForearmShape()), FOREARM_REGION, tiling)


def test_custom_part_on_the_real_baxter_w0(shared_data) -> None:
    with pytest.warns(MeshRepaired, match="non-manifold edges removed"):  # a CAD export's faults
        part = custom_part(
            shared_data / "baxter" / "upper_forearm_W0.STL", W0_REGION, W0_TILING, "w0"
        )
    assert part.n_taxels == 768
    closest, _ = closest_on_mesh(part.link, part.layout.positions_m)
    assert np.linalg.norm(closest - part.layout.positions_m, axis=1).max() < 1e-4
    tmap = TactileMap.build(part.layout, step_mm=2.0)
    assert np.isfinite(tmap.uv).all()


def test_part_command_writes_the_model_and_names_bad_flags(tmp_path):
    """`handskin part plate --out DIR`: MJCF model and scene, link STL and a layout that loads back
    as the part's; a bad --step-mm is refused naming the flag."""
    import typer
    from typer.testing import CliRunner

    from sim.cli.parts import register
    from tactile.geometry.layout import TaxelLayout

    app = typer.Typer()
    register(app)
    result = CliRunner().invoke(app, ["part", "plate", "--out", str(tmp_path)])
    assert result.exit_code == 0, result.output
    folder = tmp_path / "plate"
    assert {p.name for p in folder.iterdir()} >= {"plate.xml", "scene.xml", "plate_link.stl"}
    layout = TaxelLayout.load(folder / "plate_layout.npz")
    assert np.array_equal(layout.positions_m, get_part("plate").layout.positions_m)
    result = CliRunner().invoke(app, ["part", "plate", "--step-mm", "-1"])
    assert result.exit_code == 2 and "--step-mm -1.0 is out of range" in result.output
    result = CliRunner().invoke(app, ["probe", "--n-forces", "1"])
    assert result.exit_code == 2 and "--n-forces 1 is out of range" in result.output
