"""Denser forearm skins (`forearm_x2`, `forearm_x3`, `forearm_x4`): the forearm's box, smaller
modules; the default one marks a single pad on the default grid as a real CySkin pad."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from sim.skin import DEFAULT_PART, MAP_STEP_MM
from sim.skin.parts import FOREARM_TILING, SKIN_PITCH_MM, finer_forearm_tiling, get_part
from sim.skin.tiling import module_lattice
from tactile.errors import ConfigError
from tactile.figures.maps import coverage_mask
from tactile.images.tactile_map import TactileMap

ROWS = {"forearm_x2": 7, "forearm_x3": 9, "forearm_x4": 10}


def test_five_rows_is_the_forearm_itself() -> None:
    """The rule redraws the hand-written forearm tiling, bare slot included, from its own box."""
    assert finer_forearm_tiling(5) == FOREARM_TILING


def bare_centroid_mm() -> np.ndarray:
    centres, _ = module_lattice(5, 13, FOREARM_TILING.col_pitch_mm, FOREARM_TILING.row_pitch_mm)
    return centres[~FOREARM_TILING.slots()][0]


@pytest.mark.parametrize("name", sorted(ROWS))
def test_pitch_density_box_and_hole(name: str) -> None:
    rows = ROWS[name]
    part = get_part(name)
    tiling = finer_forearm_tiling(rows)
    pitch = SKIN_PITCH_MM * 5 / rows
    # 3D nearest-neighbour distance of the tactile pads (6 and 10 are the iCub's thermal ones):
    # the scaled pitch (curvature shortens chords a little).
    pads = part.layout.positions_m[~np.isin(part.layout.channel_ids % 12, (6, 10))] * 1e3
    d, _ = cKDTree(pads).query(pads, 2)
    assert np.median(d[:, 1]) == pytest.approx(pitch, rel=0.03)
    # Same box: the flat pads span the forearm's within 4 % each way.
    forearm = get_part("forearm")
    np.testing.assert_allclose(np.ptp(part.flat_mm, 0), np.ptp(forearm.flat_mm, 0), rtol=0.04)

    # Taxels per covered area of the map: (rows / 5)² times the forearm's, within 6 %.
    def density(p) -> float:
        tmap = TactileMap.build(p.layout, step_mm=1.0)
        return p.n_taxels / (coverage_mask(tmap).sum() * tmap.step_mm**2)

    assert density(part) / density(forearm) == pytest.approx((rows / 5) ** 2, rel=0.06)
    # The forearm's bare module stays bare: no pad within a pitch of its centroid.
    hole = bare_centroid_mm()
    for p in (forearm, part):
        assert np.min(np.linalg.norm(p.flat_mm - hole, axis=1)) > pitch
    assert (~tiling.slots()).sum() >= 1
    assert tiling.slots().sum() * 12 == part.n_taxels


def test_finer_forearm_refuses_no_rows() -> None:
    with pytest.raises(ConfigError, match="n_rows >= 1"):
        finer_forearm_tiling(0)


def test_the_default_skin_marks_a_single_pad_as_a_real_pad() -> None:
    """A real print's single-pad mark covers 250-300 px (docs/stats.md, ../shared/data/
    real_hands): one pressed taxel of the default skin, on the default grid, through the paper's
    image (grey level above 4 after erosion r 2 and dilation r 4), median over 60 taxels."""
    part = get_part(DEFAULT_PART)
    tmap = TactileMap.build(part.layout, step_mm=MAP_STEP_MM)
    areas = []
    for k in np.random.default_rng(0).choice(tmap.n_taxels, 60, replace=False):
        p = np.zeros(tmap.n_taxels)
        p[k] = 1.0
        areas.append(int((tmap.image(p) > 4).sum()))
    assert 250 <= np.median(areas) <= 300, np.median(areas)


def test_the_default_skin_draws_the_papers_map() -> None:
    """The paper's map, 247 x 362 px, is 182 mm around x 266 mm along at `MAP_STEP_MM` (its
    columns along the link: docs/stats.md). The default skin's map has that frame within 4 %
    each way, its pads at forearm_x3's pitch, and its columns run along the link axis (+z):
    a pixel column step moves the taxels along z only."""
    part = get_part(DEFAULT_PART)
    tmap = TactileMap.build(part.layout, step_mm=MAP_STEP_MM)
    np.testing.assert_allclose(tmap.shape, (247, 362), rtol=0.04)
    pads = part.layout.positions_m[~np.isin(part.layout.channel_ids % 12, (6, 10))] * 1e3
    d, _ = cKDTree(pads).query(pads, 2)
    assert np.median(d[:, 1]) == pytest.approx(SKIN_PITCH_MM * 5 / 9, rel=0.03)
    uv = np.asarray(tmap.vertex_uv_mm)
    xyz = part.layout.positions_m[np.asarray(tmap.vertex_taxel)]
    coef, *_ = np.linalg.lstsq(np.column_stack([uv, np.ones(len(uv))]), xyz, rcond=None)
    along_u = coef[0] / np.linalg.norm(coef[0])  # d(position)/du: the column direction
    assert abs(along_u[2]) > 0.99
