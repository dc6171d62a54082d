"""Surface mesh over taxel clouds: synthetic lattices with known triangles, and real iCub skins."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import Delaunay

from tactile.errors import MapError
from tactile.geometry.layout import TaxelLayout
from tactile.geometry.surface import triangulate
from tactile.geometry.synthetic import cylinder_sector_layout
from tactile.images.tactile_map import TactileMap

PITCH_MM = 11.0


def _edge_face_counts(faces: np.ndarray) -> np.ndarray:
    e = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)[1]


def _face_normals(p: np.ndarray, faces: np.ndarray) -> np.ndarray:
    return np.cross(p[faces[:, 1]] - p[faces[:, 0]], p[faces[:, 2]] - p[faces[:, 0]])


def _equilateral_delaunay(flat_mm: np.ndarray) -> set[tuple[int, ...]]:
    """Reference: the equilateral triangles of the flat lattice's Delaunay triangulation."""
    tri = Delaunay(flat_mm).simplices
    edge = np.linalg.norm(flat_mm[tri] - flat_mm[np.roll(tri, 1, axis=1)], axis=2).max(axis=1)
    return {tuple(sorted(t)) for t in tri[edge < 1.01 * PITCH_MM].tolist()}


@pytest.mark.parametrize("radius_m", [0.075, 0.03])
@pytest.mark.parametrize("given_normals", [True, False])
def test_cylinder_sector_matches_flat_delaunay(radius_m: float, given_normals: bool) -> None:
    layout, flat = cylinder_sector_layout(
        radius_m=radius_m, width_mm=150.0, length_mm=200.0, pitch_mm=11.0
    )
    mesh = triangulate(layout.positions_m, layout.normals if given_normals else None)
    got = {tuple(sorted(t)) for t in mesh.faces.tolist()}
    assert _equilateral_delaunay(flat) <= got  # every lattice triangle is found
    assert len(mesh.isolated) == 0
    assert _edge_face_counts(mesh.faces).max() <= 2
    outward = np.einsum(
        "ij,ij->i",
        _face_normals(layout.positions_m, mesh.faces),
        layout.normals[mesh.faces].mean(axis=1),
    )
    assert (outward > 0).all()
    assert np.allclose(mesh.spacing_m, PITCH_MM * 1e-3, rtol=0.02)


def test_hole_stays_a_hole() -> None:
    layout, flat = cylinder_sector_layout(
        radius_m=0.05, width_mm=150.0, length_mm=200.0, pitch_mm=11.0
    )
    keep = np.linalg.norm(flat, axis=1) > 25.0
    mesh = triangulate(layout.positions_m[keep], layout.normals[keep])
    centre = flat[keep][mesh.faces].mean(axis=1)
    assert np.linalg.norm(centre, axis=1).min() > 20.0  # no triangle lies over the hole
    assert len(mesh.isolated) == 0


def test_separate_patches_are_not_bridged_and_far_taxel_is_isolated() -> None:
    layout, _ = cylinder_sector_layout(radius_m=0.05, width_mm=80.0, length_mm=100.0, pitch_mm=11.0)
    p = layout.positions_m
    shifted = p + np.array([0.0, 0.15, 0.0])  # a second patch 50 mm beyond the first
    far = p[:1] + np.array([[0.0, -0.1, 0.0]])
    mesh = triangulate(np.concatenate([p, shifted, far]))
    n = len(p)
    side = np.concatenate([np.zeros(n), np.ones(n), [2]])[mesh.faces]
    assert (side.min(axis=1) == side.max(axis=1)).all()
    assert mesh.isolated.tolist() == [2 * n]


def test_degenerate_input_raises() -> None:
    line = np.column_stack([np.linspace(0, 0.1, 10), np.zeros(10), np.zeros(10)])
    with pytest.raises(MapError):
        triangulate(line)
    with pytest.raises(MapError):
        triangulate(np.zeros((2, 3)))
    with pytest.raises(MapError):
        triangulate(np.full((5, 3), np.nan))


def _load(folder: Path, name: str) -> TaxelLayout:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # merged duplicate positions are expected
        return TaxelLayout.load(folder / f"{name}.txt")


@pytest.mark.parametrize("name", ["left_forearm_V2", "left_arm", "torso"])
def test_icub_module_gaps_are_bridged(icub_positions: Path, name: str) -> None:
    """Modules whose nearest taxels are < 9 mm apart share at least one triangle."""
    layout = _load(icub_positions, name)
    mesh = triangulate(layout.positions_m, layout.normals)
    mod = layout.module_ids
    p = layout.positions_m
    linked = {tuple(sorted(set(mod[f].tolist()))) for f in mesh.faces if len(set(mod[f])) > 1}
    ids = np.unique(mod)
    for i, a in enumerate(ids):
        for b in ids[i + 1 :]:
            gap = np.linalg.norm(p[mod == a][:, None] - p[mod == b][None], axis=2).min()
            if gap < 9e-3:
                assert any(a in pair and b in pair for pair in linked), (a, b, gap)
    assert _edge_face_counts(mesh.faces).max() <= 2
    assert len(mesh.isolated) <= 0.1 * layout.n_taxels


def test_icub_noisy_mesh_layout_builds_and_reports(icub_positions: Path) -> None:
    layout = _load(icub_positions, "left_forearm_mesh")
    mesh = triangulate(layout.positions_m, layout.normals)
    assert len(mesh.faces) > layout.n_taxels  # a surface, not a few scraps
    assert mesh.n_rejected_long > 0  # noisy positions give long candidates: counted
    assert mesh.isolated.dtype == np.int64
    assert _edge_face_counts(mesh.faces).max() <= 2


def _flat_module_plate(round_trip: bool) -> np.ndarray:
    """iCub-style modules on a plane at z = 0, (384, 3) m: every module has rows of 3 and 4
    exactly collinear pads. round_trip: positions moved 0.1 m away and back (a frame change), so
    rows stay collinear to within rounding (what made the old code emit zero-area triangles)."""
    from sim.skin.tiling import Tiling

    flat_mm, _, _ = Tiling(4, 8, col_pitch_mm=20.7, row_pitch_mm=35.9).flat()
    xy = flat_mm * 1e-3
    if round_trip:
        xy = (xy + 0.1) - 0.1
    return np.column_stack([xy, np.zeros(len(xy))])


def _area_m2(p: np.ndarray, faces: np.ndarray) -> np.ndarray:
    return 0.5 * np.linalg.norm(_face_normals(p, faces), axis=1)


@pytest.mark.parametrize("round_trip", [False, True])
def test_collinear_pads_on_a_flat_plate_give_no_slivers(round_trip: bool) -> None:
    p = _flat_module_plate(round_trip)
    normals = np.tile([0.0, 0.0, 1.0], (len(p), 1))
    mesh = triangulate(p, normals)
    spacing = np.median(mesh.spacing_m[mesh.faces], axis=1)
    assert (_area_m2(p, mesh.faces) >= 1e-4 * spacing**2).all()
    assert len(mesh.isolated) == 0
    # Same coverage as the triangulation of the same pads in general position (1 µm jitter).
    jittered = p + np.random.default_rng(0).normal(0.0, 1e-6, p.shape) * [1, 1, 0]
    reference = triangulate(jittered, normals)
    assert _area_m2(p, mesh.faces).sum() == pytest.approx(
        _area_m2(jittered, reference.faces).sum(), rel=1e-3
    )
    tmap = TactileMap.build(TaxelLayout(p, normals))
    assert tmap.distortion.summary()["n_flipped"] == 0
    assert np.isfinite(tmap.uv).all()
