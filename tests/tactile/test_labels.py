"""Hand-part labels: label images consistent with the tactile image, back-projection, summaries."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import Delaunay

from tactile.errors import MapError
from tactile.geometry.synthetic import cylinder_sector_layout
from tactile.images.labels import (
    CLASS_NAMES,
    PALETTE,
    PartSummary,
    backproject,
    colorize,
    label_image,
    part_summary,
)
from tactile.images.morphology import dilate
from tactile.images.resize import resize_labels
from tactile.images.tactile_map import TactileMap


@pytest.fixture(scope="module")
def forearm() -> TactileMap:
    layout, flat_mm = cylinder_sector_layout()
    uv = np.column_stack([flat_mm[:, 1], -flat_mm[:, 0]])
    return TactileMap.from_flat(layout.positions_m, uv, np.arange(len(uv)), Delaunay(uv).simplices)


def two_contacts(tmap: TactileMap) -> tuple[np.ndarray, np.ndarray]:
    """Thumb (1) presses a disk around (-100, 40) mm, palm (6) a disk around (80, -50) mm."""
    p, labels = np.zeros(tmap.n_taxels), np.zeros(tmap.n_taxels, dtype=np.int64)
    for cls, centre in ((1, (-100.0, 40.0)), (6, (80.0, -50.0))):
        d = np.linalg.norm(tmap.uv - centre, axis=1)
        pressed = d < 25.0
        p[pressed] = 3e4 * (1.2 - d[pressed] / 25.0)  # Pa
        labels[pressed] = cls
    return p, labels


def test_palette_and_names() -> None:
    assert CLASS_NAMES[0] == "background" and len(CLASS_NAMES) == 7
    assert PALETTE.shape == (7, 3) and PALETTE.dtype == np.uint8
    assert not PALETTE[0].any()
    assert len({tuple(c) for c in PALETTE}) == 7
    assert colorize(np.array([[0, 6]])).shape == (1, 2, 3)


def test_precomputed_image_gives_the_same_labels_and_unlabelled_skips_it(
    forearm: TactileMap, monkeypatch: pytest.MonkeyPatch
) -> None:
    p, labels = two_contacts(forearm)
    want = forearm.label_image(p, labels)
    image = forearm.image(p)
    calls = []
    monkeypatch.setattr(TactileMap, "image", lambda *a, **k: calls.append(1))
    np.testing.assert_array_equal(label_image(forearm, p, labels, image=image), want)
    blank = label_image(forearm, p, np.zeros_like(labels))  # a non-hand contact: no class
    assert not calls and blank.shape == forearm.shape and not blank.any()
    with pytest.raises(MapError, match="shape"):
        label_image(forearm, p, labels, image=image[:-1])


def reference_label_image(
    tmap: TactileMap, p: np.ndarray, labels: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The documented rule written out slowly: every class's field dilated on the whole map, the
    class of the largest (lowest class on exact ties) where the image is lit; and where the two
    largest differ, by at most 8 ulps (a near tie: either class)."""
    fields = np.stack([np.where(labels == c, p, 0.0) for c in range(7)])
    spread = np.stack([dilate(f, 4) for f in tmap.interpolate(fields)])
    top = np.sort(spread, axis=0)[-2:]
    gap = top[1] - top[0]
    near = (gap > 0) & (gap <= 8 * np.spacing(top[1]))
    lit = tmap.image(p) > 0
    return np.where(lit, spread.argmax(axis=0), 0).astype(np.uint8), near & lit


def test_label_image_is_the_slow_rule_but_at_near_ties(forearm: TactileMap) -> None:
    rng = np.random.default_rng(0)
    for trial in range(30):
        p, labels = np.zeros(forearm.n_taxels), np.zeros(forearm.n_taxels, dtype=np.int64)
        idx = rng.choice(forearm.n_taxels, int(rng.integers(1, 40)), replace=False)
        levels = [1.0, 2.0] if trial % 2 else list(rng.uniform(1e2, 5e4, 4))  # ties, then not
        p[idx], labels[idx] = rng.choice(levels, idx.size), rng.integers(0, 7, idx.size)
        want, near = reference_label_image(forearm, p, labels)
        got = label_image(forearm, p, labels)
        np.testing.assert_array_equal(got[~near], want[~near])


def test_separated_regions_get_their_class(forearm: TactileMap) -> None:
    p, labels = two_contacts(forearm)
    seg = forearm.label_image(p, labels)
    image = forearm.image(p)
    assert seg.shape == forearm.shape and seg.dtype == np.uint8
    np.testing.assert_array_equal(seg == 0, image == 0)  # labelled exactly where the image is lit
    centres = forearm.pixel_centers()
    near_thumb = np.linalg.norm(centres - (-100.0, 40.0), axis=-1) < 40.0
    near_palm = np.linalg.norm(centres - (80.0, -50.0), axis=-1) < 40.0
    assert set(np.unique(seg[near_thumb])) == {0, 1}
    assert set(np.unique(seg[near_palm])) == {0, 6}
    assert not seg[~(near_thumb | near_palm)].any()


def test_backproject_recovers_pressed_taxels(forearm: TactileMap) -> None:
    p, labels = two_contacts(forearm)
    recovered = backproject(forearm, forearm.label_image(p, labels))
    pressed = p > 0
    np.testing.assert_array_equal(recovered[pressed], labels[pressed])
    far = np.linalg.norm(forearm.uv - (0.0, 0.0), axis=1) < 30.0
    assert not recovered[far].any()
    batch = backproject(forearm, np.stack([forearm.label_image(p, labels)] * 2))
    assert batch.shape == (2, forearm.n_taxels)
    np.testing.assert_array_equal(batch[1], recovered)


def test_backproject_majority_in_radius(forearm: TactileMap) -> None:
    seg = np.zeros(forearm.shape, dtype=np.uint8)
    seg[:, : forearm.shape[1] // 2] = 3
    labels = backproject(forearm, seg, radius_mm=3.0)
    u_split = forearm.origin_mm[0] + forearm.shape[1] // 2 * forearm.step_mm
    clear = np.abs(forearm.uv[:, 0] - u_split) > 4.0
    np.testing.assert_array_equal(labels[clear], np.where(forearm.uv[clear, 0] < u_split, 3, 0))


def test_part_summary_by_hand() -> None:
    labels = np.array([0, 1, 1, 1, 6, 2, 0])
    p = np.array([9.0, 2.0, 4.0, 0.0, 5.0, 0.0, 1.0])
    summary = part_summary(labels, p)
    assert list(summary) == list(CLASS_NAMES[1:])
    assert summary["thumb"] == PartSummary(2, 3.0)  # taxels 1, 2 pressed; 3 reads zero
    assert summary["palm"] == PartSummary(1, 5.0)
    assert summary["index"] == PartSummary(0, 0.0)  # labelled but not pressed
    assert summary["middle"] == PartSummary(0, 0.0)
    assert part_summary(labels, p, threshold=3.0)["thumb"] == PartSummary(1, 4.0)


def test_bad_labels_raise(forearm: TactileMap) -> None:
    p = np.zeros(forearm.n_taxels)
    with pytest.raises(MapError, match=r"0\.\.6"):
        forearm.label_image(p, np.full(forearm.n_taxels, 7))
    with pytest.raises(MapError, match="integer"):
        forearm.label_image(p, np.zeros(forearm.n_taxels))
    with pytest.raises(MapError, match="seg must be"):
        backproject(forearm, np.zeros((4, 4), dtype=np.uint8))


def test_resize_labels_nearest_keeps_classes() -> None:
    lbl = np.zeros((247, 362), dtype=np.uint8)
    lbl[50:150, 100:200] = 4
    lbl[200:, 300:] = 6
    small = resize_labels(lbl, (68, 100))
    assert small.shape == (68, 100) and small.dtype == np.uint8
    assert set(np.unique(small)) == {0, 4, 6}
    assert small[int(100 * 68 / 247), int(150 * 100 / 362)] == 4
    batch = resize_labels(np.stack([lbl, lbl]), (68, 100))
    np.testing.assert_array_equal(batch[1], small)
    np.testing.assert_array_equal(resize_labels(lbl, lbl.shape), lbl)


def _label_image_all_classes(tmap, p, labels, erode_px=2, dilate_px=4):
    """Reference: every class field at full size, dilated, arg-max where the image is lit."""
    from tactile.images import morphology

    image = tmap.image(p, erode_px=erode_px, dilate_px=dilate_px)
    fields = np.where(labels[None, :] == np.arange(7)[:, None], p[None, :], 0.0)
    spread = morphology.dilate(np.ascontiguousarray(tmap.interpolate(fields)), dilate_px)
    return np.where(image > 0, spread.argmax(axis=0), 0).astype(np.uint8)


@pytest.mark.parametrize("seed", range(6))
def test_label_image_equals_the_all_classes_reference(seed: int):
    layout, flat_mm = cylinder_sector_layout()
    tmap = TactileMap.from_flat(
        layout.positions_m, flat_mm, np.arange(layout.n_taxels), Delaunay(flat_mm).simplices
    )
    rng = np.random.default_rng(seed)
    centre = flat_mm[rng.integers(layout.n_taxels)]
    near = np.linalg.norm(flat_mm - centre, axis=1) < rng.uniform(20, 90)
    p = np.where(near, rng.uniform(0, 5e4, layout.n_taxels), 0.0)
    labels = np.where(near, rng.integers(0, 7 if seed % 2 else 3, layout.n_taxels), 0)
    np.testing.assert_array_equal(
        label_image(tmap, p, labels), _label_image_all_classes(tmap, p, labels)
    )


def test_contact_instances_groups_by_gap_orders_by_load_and_drops_noise():
    """Three pressed groups on a line (taxels 10 mm apart in each, groups 80 mm apart) and a
    lone taxel: a chain of 10 mm steps is one contact, 80 mm is a gap, the lone taxel is noise;
    contacts are numbered by summed pressure."""
    from tactile.images.labels import contact_instances

    x = np.concatenate([np.arange(4) * 0.01, 0.11 + np.arange(5) * 0.01, [0.30]])
    positions = np.column_stack([x, np.zeros_like(x), np.zeros_like(x)])
    p = np.array([1.0] * 4 + [3.0] * 5 + [9.0])
    got = contact_instances(positions, p, threshold=0.5, gap_m=0.05, min_taxels=3)
    np.testing.assert_array_equal(got, [2, 2, 2, 2, 1, 1, 1, 1, 1, 0])
    p[1] = 0.0  # a released taxel splits nothing here (10 mm + 10 mm < 50 mm) and is not pressed
    assert contact_instances(positions, p, threshold=0.5, gap_m=0.05)[1] == 0
    assert contact_instances(positions, np.zeros(len(x))).max() == 0
