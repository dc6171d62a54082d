"""TactileMap: grid, interpolation (vs matplotlib), the paper's image (vs skimage), I/O, errors."""

from __future__ import annotations

from pathlib import Path

import matplotlib.tri as mtri
import numpy as np
import pytest
from scipy.spatial import Delaunay
from skimage.morphology import dilation, disk, erosion

from tactile.errors import MapError
from tactile.geometry.synthetic import cylinder_sector_layout
from tactile.images.resize import resize_image
from tactile.images.tactile_map import TactileMap


def flat_forearm(**kw: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions (N, 3) m, exact flat uv (N, 2) mm (long axis along u), Delaunay faces (M, 3)."""
    layout, flat_mm = cylinder_sector_layout(**{"pitch_mm": 11.0, **kw})
    uv = np.column_stack([flat_mm[:, 1], -flat_mm[:, 0]])  # a rotation: (s, z) -> (z, -s)
    return layout.positions_m, uv, Delaunay(uv).simplices


@pytest.fixture(scope="module")
def forearm() -> TactileMap:
    pos, uv, faces = flat_forearm()
    return TactileMap.from_flat(pos, uv, np.arange(len(uv)), faces)


def blobs(tmap: TactileMap, centres_mm: list[tuple[float, float]], sigma_mm: float) -> np.ndarray:
    """Gaussian pressure blobs (Pa) at uv centres, zero beyond 2 sigma."""
    d2 = ((tmap.uv[:, None, :] - np.asarray(centres_mm)[None]) ** 2).sum(-1)
    p = (1e4 * np.exp(-d2 / (2 * sigma_mm**2)) * (d2 < 4 * sigma_mm**2)).sum(axis=1)
    return p


def reference_interpolation(tmap: TactileMap, p: np.ndarray) -> np.ma.MaskedArray:
    """matplotlib's LinearTriInterpolator on the map's own flat mesh, at every pixel centre."""
    tri = mtri.Triangulation(*tmap.vertex_uv_mm.T, tmap.faces)
    centres = tmap.pixel_centers()
    return mtri.LinearTriInterpolator(tri, p[tmap.vertex_taxel])(centres[..., 0], centres[..., 1])


def test_grid_of_a_247_by_362_mm_map() -> None:
    uv = np.array([[0.0, 0.0], [362.0, 0.0], [362.0, 247.0], [0.0, 247.0]]) + np.array([10.0, -5.0])
    pos = np.column_stack([uv * 1e-3, np.zeros(4)])
    tmap = TactileMap.from_flat(pos, uv, np.arange(4), np.array([[0, 1, 2], [0, 2, 3]]))
    assert tmap.shape == (247, 362)
    centres = tmap.pixel_centers()
    np.testing.assert_allclose(centres[0, 0], [10.5, 241.5])  # top-left: u_min + .5, v_max - .5
    np.testing.assert_allclose(centres[-1, -1], [371.5, -4.5])
    assert tmap.coverage().all()
    assert tmap.image(np.ones(4)).min() == 255


def test_interpolate_equals_matplotlib(forearm: TactileMap) -> None:
    p = np.random.default_rng(0).random(forearm.n_taxels) * 5e3
    ours, ref = forearm.interpolate(p), reference_interpolation(forearm, p)
    outside = np.ma.getmaskarray(ref)
    assert 0 < outside.sum() < 0.05 * outside.size
    np.testing.assert_array_equal(ours[outside], 0.0)
    np.testing.assert_allclose(ours[~outside], ref.data[~outside], rtol=1e-9, atol=1e-9 * p.max())


def test_seam_vertices_map_to_their_taxels() -> None:
    """Vertices in another order than the taxels (as after cutting seams) use vertex_taxel."""
    vertex_pos, uv, faces = flat_forearm(width_mm=60.0, length_mm=80.0)
    vertex_taxel = np.random.default_rng(3).permutation(len(uv))
    pos = np.empty_like(vertex_pos)
    pos[vertex_taxel] = vertex_pos
    tmap = TactileMap.from_flat(pos, uv, vertex_taxel, faces)
    p = np.random.default_rng(4).random(len(uv))
    ref = reference_interpolation(tmap, p)
    inside = ~np.ma.getmaskarray(ref)
    np.testing.assert_allclose(tmap.interpolate(p)[inside], ref.data[inside], rtol=1e-9)
    np.testing.assert_array_equal(tmap.triangles, vertex_taxel[faces])


def test_linear_field_is_reproduced_exactly(forearm: TactileMap) -> None:
    a, b, c = 3.0, -2.0, 2000.0  # Pa/mm, Pa/mm, Pa
    p = a * forearm.uv[:, 0] + b * forearm.uv[:, 1] + c
    centres = forearm.pixel_centers()
    expected = a * centres[..., 0] + b * centres[..., 1] + c
    inside = forearm.coverage()
    np.testing.assert_allclose(forearm.interpolate(p)[inside], expected[inside], rtol=1e-12)


def test_batched_interpolate_equals_frames(forearm: TactileMap) -> None:
    p = np.random.default_rng(5).random((3, forearm.n_taxels))
    batch = forearm.interpolate(p)
    assert batch.shape == (3, *forearm.shape)
    for frame, k in zip(p, batch, strict=True):
        np.testing.assert_allclose(k, forearm.interpolate(frame), rtol=1e-12, atol=1e-15)
    single = forearm.interpolate(p, dtype=np.float32)
    np.testing.assert_allclose(single, batch, rtol=1e-5, atol=1e-6)


def test_box_interpolation_equals_the_whole_grid(forearm: TactileMap) -> None:
    """One frame's box is gathered per pixel, a batch's through the table's rows; both are the
    whole grid's values on the box. Each pixel sums its taxels in the table's order, so they
    agree to the last bit unless a build of scipy fuses multiply-adds (1 ulp: rtol 1e-12)."""
    rng = np.random.default_rng(9)
    p = rng.random((4, forearm.n_taxels)) * (rng.random((4, forearm.n_taxels)) < 0.3)
    rows, cols = slice(5, forearm.shape[0] - 7), slice(11, forearm.shape[1] // 2)
    whole = forearm.interpolate(p)[:, rows, cols]
    np.testing.assert_allclose(forearm.interpolate_box(p, rows, cols), whole, rtol=1e-12, atol=0)
    for frame, expected in zip(p, whole, strict=True):
        box = forearm.interpolate_box(frame, rows, cols)
        np.testing.assert_allclose(box, expected, rtol=1e-12, atol=0)


def slow_image(tmap: TactileMap, p: np.ndarray, erode_px: int, dilate_px: int) -> np.ndarray:
    """The paper's image, written directly: matplotlib K, floor formula, skimage morphology."""
    k = reference_interpolation(tmap, p).filled(0.0)
    grey = np.floor(255.0 * k / p.max() + 1e-9) if p.max() > 0 else np.zeros_like(k)
    grey = np.clip(grey, 0, 255).astype(np.uint8)  # K can be -1e-17 by round-off
    return dilation(erosion(grey, disk(erode_px)), disk(dilate_px))


@pytest.mark.parametrize(("erode_px", "dilate_px"), [(2, 4), (0, 3), (1, 0)])
def test_image_equals_direct_reference(forearm: TactileMap, erode_px: int, dilate_px: int) -> None:
    rng = np.random.default_rng(erode_px)
    frames = [
        blobs(forearm, [(-100.0, 30.0), (60.0, -70.0), (170.0, 100.0)], 12.0),
        rng.random(forearm.n_taxels) * (rng.random(forearm.n_taxels) < 0.2),
    ]
    for p in frames:
        ours = forearm.image(p, erode_px=erode_px, dilate_px=dilate_px)
        assert ours.dtype == np.uint8
        np.testing.assert_array_equal(ours, slow_image(forearm, p, erode_px, dilate_px))
    batch = forearm.image(np.stack(frames), erode_px=erode_px, dilate_px=dilate_px)
    np.testing.assert_array_equal(batch[1], slow_image(forearm, frames[1], erode_px, dilate_px))


def test_zero_frame_gives_black_image(forearm: TactileMap) -> None:
    assert not forearm.image(np.zeros(forearm.n_taxels)).any()
    assert not forearm.image(np.zeros((2, forearm.n_taxels))).any()


def test_save_load_round_trip(forearm: TactileMap, tmp_path: Path) -> None:
    path = tmp_path / "forearm_map.npz"
    forearm.save(path)
    loaded = TactileMap.load(path)
    p = np.random.default_rng(6).random((2, forearm.n_taxels))
    np.testing.assert_array_equal(loaded.interpolate(p), forearm.interpolate(p))
    assert loaded.shape == forearm.shape and loaded.step_mm == forearm.step_mm
    for name in ("uv", "vertex_uv_mm", "vertex_taxel", "faces", "positions_m", "origin_mm"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(forearm, name))
    assert loaded.distortion.summary() == forearm.distortion.summary()


def test_load_rejects_other_files(tmp_path: Path) -> None:
    np.savez(tmp_path / "other.npz", a=np.zeros(3))
    with pytest.raises(MapError, match="not a tactile map"):
        TactileMap.load(tmp_path / "other.npz")
    with pytest.raises(MapError, match="cannot read"):
        TactileMap.load(tmp_path / "missing.npz")


def test_bad_pressures_raise(forearm: TactileMap) -> None:
    n = forearm.n_taxels
    with pytest.raises(MapError, match=f"\\({n},\\)"):
        forearm.interpolate(np.zeros(n - 1))
    p = np.zeros(n)
    p[17] = np.nan
    with pytest.raises(MapError, match="taxel 17"):
        forearm.image(p)
    batch = np.zeros((3, n))
    batch[2, 5] = np.inf
    with pytest.raises(MapError, match="taxel 5 of frame 2"):
        forearm.interpolate(batch)


def test_bad_flat_mesh_raises() -> None:
    pos, uv, faces = flat_forearm(width_mm=40.0, length_mm=40.0)
    ids = np.arange(len(uv))
    with pytest.raises(MapError, match="faces must index vertices"):
        TactileMap.from_flat(pos, uv, ids, faces + len(uv))
    with pytest.raises(MapError, match="vertex_uv_mm row 2"):
        TactileMap.from_flat(pos, np.where(ids[:, None] == 2, np.nan, uv), ids, faces)
    with pytest.raises(MapError, match="in mm"):
        TactileMap.from_flat(pos, uv * 1e3, ids, faces)
    with pytest.raises(MapError, match="step_mm"):
        TactileMap.from_flat(pos, uv, ids, faces, step_mm=0.0)


def test_build_from_layout() -> None:
    layout, _ = cylinder_sector_layout()
    tmap = TactileMap.build(layout)
    assert abs(tmap.shape[0] - 239) <= 2 and abs(tmap.shape[1] - 358) <= 2
    assert tmap.distortion.n_flipped == 0
    assert tmap.coverage().mean() > 0.95
    p = np.ones(layout.n_taxels)
    np.testing.assert_allclose(tmap.interpolate(p)[tmap.coverage()], 1.0)
    with pytest.raises(MapError, match="known options"):
        TactileMap.build(layout, max_edge=3.0)


def test_resize_image_keeps_dtype_and_batches(forearm: TactileMap) -> None:
    img = forearm.image(blobs(forearm, [(0.0, 0.0)], 20.0))
    small = resize_image(img)
    assert small.shape == (68, 100) and small.dtype == np.uint8
    assert abs(float(small.mean()) - float(img.mean())) < 2.0  # anti-aliased average kept
    batch = resize_image(np.stack([img, img[::-1]]).astype(np.float32), (34, 50))
    assert batch.shape == (2, 34, 50) and batch.dtype == np.float32
    np.testing.assert_array_equal(batch[0], resize_image(img.astype(np.float32), (34, 50)))


def test_resize_keep_support_matches_nearest_labels(forearm: TactileMap) -> None:
    """keep_support: non-zero exactly on the nearest-neighbour support, checked pixel by pixel
    against the centre-rule nearest source pixel, values the plain resize's where those are at
    least the smallest positive input; frames of a batch independent of each other."""
    img = forearm.image(blobs(forearm, [(0.0, 0.0), (60.0, -40.0)], 20.0))
    h, w = 68, 100
    plain = resize_image(img, (h, w))
    kept = resize_image(img, (h, w), keep_support=True)
    assert kept.dtype == np.uint8
    H, W = img.shape
    for i in range(h):
        for j in range(w):
            src = img[min(int((i + 0.5) * H / h), H - 1), min(int((j + 0.5) * W / w), W - 1)]
            if src == 0:
                assert kept[i, j] == 0
            else:
                assert kept[i, j] == max(plain[i, j], img[img > 0].min())
    x = img.astype(np.float32) / 255
    assert (resize_image(x, (h, w)) > 0).sum() > 1.2 * (kept > 0).sum()  # blur widens a float
    batch = resize_image(np.stack([x, np.zeros_like(x), x[::-1] * 0.5]), (h, w), keep_support=True)
    np.testing.assert_array_equal(batch[0], resize_image(x, (h, w), keep_support=True))
    np.testing.assert_array_equal(batch[0] > 0, kept > 0)
    np.testing.assert_array_equal(batch[1], 0)
    np.testing.assert_array_equal(batch[2], resize_image(x[::-1] * 0.5, (h, w), keep_support=True))
