"""Flattening: isometry on developable lattices, seams on tubes, holes kept, real iCub skins."""

from __future__ import annotations

import csv
import warnings
from pathlib import Path

import numpy as np
import pytest

from tactile.errors import MapError
from tactile.geometry.distortion import signed_areas
from tactile.geometry.flatten import flatten
from tactile.geometry.layout import TaxelLayout
from tactile.geometry.seams import boundary_loops, face_components
from tactile.geometry.surface import SurfaceMesh, triangulate
from tactile.geometry.synthetic import cylinder_sector_layout

PITCH_MM = 11.0
ROW_MM = PITCH_MM * np.sqrt(3.0) / 2.0


def _rigid_residual_mm(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Distances (K,) after the best rotation + translation (no reflection, no scale) x -> y."""
    xc, yc = x - x.mean(axis=0), y - y.mean(axis=0)
    u, _, vt = np.linalg.svd(xc.T @ yc)
    d = np.sign(np.linalg.det(u @ vt))
    rot = u @ np.diag([1.0, d]) @ vt
    return np.linalg.norm(xc @ rot - yc, axis=1)


def _edge_ratio_3d(positions_m: np.ndarray, flat) -> np.ndarray:
    e = np.concatenate([flat.faces[:, [0, 1]], flat.faces[:, [1, 2]], flat.faces[:, [2, 0]]])
    l2 = np.linalg.norm(flat.vertex_uv_mm[e[:, 0]] - flat.vertex_uv_mm[e[:, 1]], axis=1)
    xyz = positions_m[flat.vertex_taxel] * 1e3
    return l2 / np.linalg.norm(xyz[e[:, 0]] - xyz[e[:, 1]], axis=1)


def _flat(layout_or_p, normals=None, **kw):
    p = getattr(layout_or_p, "positions_m", layout_or_p)
    n = getattr(layout_or_p, "normals", normals)
    return flatten(p, triangulate(p, n), **kw)


@pytest.mark.parametrize("radius_m", [0.2, 0.075, 0.03])
@pytest.mark.parametrize("method", ["arap", "lscm"])
def test_developable_patch_is_isometric(radius_m: float, method: str) -> None:
    """Edge lengths within 1 % (plus the chord-vs-arc gap of the 3D mesh on a tight radius)."""
    layout, exact = cylinder_sector_layout(
        radius_m=radius_m, width_mm=150.0, length_mm=200.0, pitch_mm=11.0
    )
    flat = _flat(layout, method=method)
    e = _edges(flat.faces)
    xyz = layout.positions_m[flat.vertex_taxel] * 1e3
    flat_exact = exact[flat.vertex_taxel]
    length3 = np.linalg.norm(xyz[e[:, 0]] - xyz[e[:, 1]], axis=1)
    arc_gap = np.linalg.norm(flat_exact[e[:, 0]] - flat_exact[e[:, 1]], axis=1) / length3 - 1.0
    ratio = (
        np.linalg.norm(flat.vertex_uv_mm[e[:, 0]] - flat.vertex_uv_mm[e[:, 1]], axis=1) / length3
    )
    tol = 0.01 if method == "arap" else 0.03  # LSCM is conformal only: looser
    assert (np.abs(ratio - 1.0) < tol + np.abs(arc_gap)).all()
    if radius_m >= 0.075:
        assert np.abs(ratio - 1.0).max() < tol
    # exact (arc length, axis) is the sector seen from outside; the map is seen from inside
    residual = _rigid_residual_mm(flat.taxel_uv_mm, exact * np.array([1.0, -1.0]))
    assert residual.max() < (1.0 if method == "arap" else 3.0)
    assert flat.n_patches == 1 and flat.seams == 0 and flat.distortion.n_flipped == 0


def test_the_map_shows_the_skin_seen_from_inside() -> None:
    """Three taxels counter-clockwise seen from outside (about their outward normal) run
    clockwise on the map: the mirror image the paper's tactile images show."""
    layout, _ = cylinder_sector_layout(
        radius_m=0.075, width_mm=150.0, length_mm=200.0, pitch_mm=11.0
    )
    flat = _flat(layout)
    p, n, uv = layout.positions_m, layout.normals, flat.taxel_uv_mm
    near = np.argsort(np.linalg.norm(p[:, None] - p[None], axis=2), axis=1)[:, 1:7]
    for a, b, c in zip(range(len(p)), near[:, 0], near[:, 2], strict=True):  # two neighbours
        outside = np.dot(np.cross(p[b] - p[a], p[c] - p[a]), n[a])
        d1, d2 = uv[b] - uv[a], uv[c] - uv[a]
        on_map = d1[0] * d2[1] - d1[1] * d2[0]
        if abs(outside) > 1e-9 and abs(on_map) > 1e-3:
            assert np.sign(on_map) == -np.sign(outside)


def _edges(faces: np.ndarray) -> np.ndarray:
    e = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    return np.unique(np.sort(e, axis=1), axis=0)


def test_canonical_orientation_and_determinism() -> None:
    layout, _ = cylinder_sector_layout(radius_m=0.05, width_mm=80.0, length_mm=250.0, pitch_mm=11.0)
    a, b = _flat(layout), _flat(layout)
    for name in ("vertex_uv_mm", "vertex_taxel", "faces", "taxel_uv_mm"):
        assert np.array_equal(getattr(a, name), getattr(b, name))
    assert (signed_areas(a.vertex_uv_mm, a.faces) > 0).all()
    extent = np.ptp(a.vertex_uv_mm, axis=0)
    assert extent[0] > 2.5 * extent[1]  # the 250 mm axis runs along u
    assert np.allclose(a.vertex_uv_mm.min(axis=0), 0.0)
    # +u follows +y (the cylinder axis, the 3D principal axis signed positive)
    y = layout.positions_m[:, 1]
    assert np.corrcoef(a.taxel_uv_mm[:, 0], y)[0, 1] > 0.99


@pytest.mark.parametrize("n_rows", [20, 12])
def test_full_tube_is_cut_into_a_strip(n_rows: int) -> None:
    radius_m = n_rows * ROW_MM / (2 * np.pi) * 1e-3  # the lattice closes round the tube
    layout, _ = cylinder_sector_layout(
        radius_m=radius_m, width_mm=(n_rows - 1) * ROW_MM + 1e-6, length_mm=150.0, pitch_mm=11.0
    )
    flat = _flat(layout)
    assert flat.seams >= 1 and flat.n_patches == 1
    assert len(flat.vertex_taxel) > layout.n_taxels  # seam taxels have two vertices
    assert np.abs(_edge_ratio_3d(layout.positions_m, flat) - 1.0).max() < 0.04
    assert flat.distortion.n_flipped == 0
    assert len(boundary_loops(flat.faces)) == 1  # a strip (disk), not a ring
    circumference_mm = 2 * np.pi * radius_m * 1e3
    seam_taxels = np.flatnonzero(np.bincount(flat.vertex_taxel) > 1)
    assert len(seam_taxels) >= 150.0 / PITCH_MM  # the seam runs the whole tube length
    for t in seam_taxels:  # the two copies of a seam taxel lie a circumference apart
        copies = flat.vertex_uv_mm[flat.vertex_taxel == t]
        assert abs(np.linalg.norm(copies[0] - copies[-1]) / circumference_mm - 1.0) < 0.05


def test_patch_with_hole_is_not_cut_and_keeps_the_hole() -> None:
    layout, exact = cylinder_sector_layout(
        radius_m=0.04, width_mm=150.0, length_mm=200.0, pitch_mm=11.0
    )
    keep = np.linalg.norm(exact - [0.0, 10.0], axis=1) > 25.0
    p, exact = layout.positions_m[keep], exact[keep]
    flat = _flat(p, layout.normals[keep])
    assert flat.seams == 0 and flat.n_patches == 1
    assert np.abs(flat.distortion.edge_ratio - 1.0).max() < 0.02
    # where the hole centre lands in uv (rigid fit of the exact lattice), no triangle covers it
    xc, yc = exact - exact.mean(axis=0), flat.taxel_uv_mm - flat.taxel_uv_mm.mean(axis=0)
    u, _, vt = np.linalg.svd(xc.T @ yc)
    centre = (np.array([0.0, 10.0]) - exact.mean(axis=0)) @ (u @ vt) + flat.taxel_uv_mm.mean(0)
    tri = flat.vertex_uv_mm[flat.faces]
    assert not any(_inside(centre, t) for t in tri)
    assert np.linalg.norm(flat.taxel_uv_mm - centre, axis=1).min() > 20.0


def _inside(point: np.ndarray, tri: np.ndarray) -> bool:
    edge = np.roll(tri, -1, axis=0) - tri
    rel = point - tri
    d = edge[:, 0] * rel[:, 1] - edge[:, 1] * rel[:, 0]
    return bool(d.min() > 0)


def test_separate_patches_are_packed_without_overlap_and_far_taxel_is_nan() -> None:
    layout, _ = cylinder_sector_layout(radius_m=0.05, width_mm=80.0, length_mm=100.0, pitch_mm=11.0)
    p = layout.positions_m
    far = p[:1] + np.array([[0.0, -0.1, 0.0]])
    positions = np.concatenate([p, p + np.array([0.0, 0.15, 0.0]), far])
    flat = _flat(positions)
    assert flat.n_patches == 2
    assert np.isnan(flat.taxel_uv_mm[-1]).all() and np.isfinite(flat.taxel_uv_mm[:-1]).all()
    n = len(p)
    boxes = [flat.taxel_uv_mm[s] for s in (slice(0, n), slice(n, 2 * n))]
    lo, hi = [b.min(axis=0) for b in boxes], [b.max(axis=0) for b in boxes]
    gap = np.maximum(lo[1] - hi[0], lo[0] - hi[1]).max()
    assert gap >= 3.0
    assert np.abs(flat.distortion.edge_ratio - 1.0).max() < 0.01


def test_degenerate_input_raises() -> None:
    layout, _ = cylinder_sector_layout(radius_m=0.05, width_mm=40.0, length_mm=40.0, pitch_mm=11.0)
    p = layout.positions_m
    empty = SurfaceMesh(np.zeros((0, 3), np.int64), np.ones(len(p)), 0, np.arange(len(p)))
    with pytest.raises(MapError, match="no triangles"):
        flatten(p, empty)
    mesh = triangulate(p)
    with pytest.raises(MapError, match="unknown flattening method"):
        flatten(p, mesh, method="tutte")
    with pytest.raises(MapError, match="index taxels"):
        flatten(p[:5], mesh)


def _load(folder: Path, name: str) -> TaxelLayout:
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # merged duplicate positions are expected
        return TaxelLayout.load(folder / f"{name}.txt")


@pytest.mark.parametrize("name", ["left_forearm_V2", "left_arm", "torso"])
def test_icub_maps(icub_positions: Path, name: str) -> None:
    layout = _load(icub_positions, name)
    flat = _flat(layout)
    assert flat.distortion.n_flipped == 0
    assert (signed_areas(flat.vertex_uv_mm, flat.faces) > 0).all()
    assert np.isfinite(flat.taxel_uv_mm).all(axis=1).mean() >= 0.9
    assert abs(np.median(_edge_ratio_3d(layout.positions_m, flat)) - 1.0) < 0.03
    summary = flat.distortion.summary()
    assert 0.97 < summary["area_ratio_median"] < 1.03
    assert summary["edge_ratio_p05"] > 0.9 and summary["edge_ratio_p95"] < 1.1


def test_icub_noisy_mesh_layout_flattens(icub_positions: Path) -> None:
    layout = _load(icub_positions, "left_forearm_mesh")
    mesh = triangulate(layout.positions_m, layout.normals)
    flat = flatten(layout.positions_m, mesh)
    assert flat.distortion.n_flipped == 0
    placed = np.isfinite(flat.taxel_uv_mm).all(axis=1)
    assert (~placed).sum() == len(mesh.isolated)


def test_icub_forearm_matches_the_hand_made_gui_layout(icub_positions: Path) -> None:
    """Neighbouring module centres: our map vs the iCub skin GUI's hand-made 2D layout."""
    layout = _load(icub_positions, "left_forearm_V2")
    gui_file = icub_positions.parent / "csv" / "left_forearm_V2_gui2d_triangles.csv"
    if not gui_file.is_file():
        pytest.skip(f"GUI layout not found at {gui_file}")
    with gui_file.open() as fh:
        gui = {int(r["id"]): np.array([float(r["u"]), float(r["v"])]) for r in csv.DictReader(fh)}
    flat = _flat(layout)
    centre = _module_centre_taxels(layout)
    patch = _taxel_patch(flat, layout.n_taxels)
    ratios = []
    for a in sorted(set(centre) & set(gui)):
        for b in sorted(set(centre) & set(gui)):
            ta, tb = centre[a], centre[b]
            d_gui = np.linalg.norm(gui[a] - gui[b])
            if a < b and d_gui < 22.0 and patch[ta] == patch[tb] >= 0:
                ratios.append(np.linalg.norm(flat.taxel_uv_mm[ta] - flat.taxel_uv_mm[tb]) / d_gui)
    assert len(ratios) >= 15
    assert abs(np.median(ratios) - 1.0) < 0.03
    assert np.percentile(ratios, 5) > 0.9 and np.percentile(ratios, 95) < 1.1


def _module_centre_taxels(layout: TaxelLayout) -> dict[int, int]:
    """Taxel at the centre pad (pad 3) of each module, merged duplicates included."""
    pairs = list(zip(layout.channel_ids.tolist(), range(layout.n_taxels), strict=True))
    if layout.merged_channels is not None:
        pairs += [tuple(row) for row in layout.merged_channels.tolist()]
    return {channel // 12: taxel for channel, taxel in pairs if channel % 12 == 3}


def _taxel_patch(flat, n_taxels: int) -> np.ndarray:
    label = face_components(flat.faces)
    vertex_patch = np.full(len(flat.vertex_uv_mm), -1)
    vertex_patch[flat.faces.ravel()] = np.repeat(label, 3)
    out = np.full(n_taxels, -1)
    out[flat.vertex_taxel[::-1]] = vertex_patch[::-1]
    return out
