"""The shared placement policy (hands and non-hands aim with the same draw) and surface frames,
checked against brute-force coverage and the forearm's closed-form cross-section."""

from __future__ import annotations

import numpy as np
import pytest

from sim.contactors import placement
from sim.contactors.interactions import MAX_GRASP_SHIFT_M, plan_hand_interaction
from sim.contactors.nonhand import sample_nonhand
from sim.contactors.spec import PressPlan
from sim.contactors.subjects import sample_subjects
from sim.episode.runner import EpisodeConfig, EpisodeContext, site_pose
from sim.skin.geometry import ForearmShape, forearm_profile, superellipse
from sim.skin.parts import PAPER_AIM_ALONG_MM, PAPER_AIM_BAND_MM, get_part


@pytest.fixture(scope="module")
def forearm():
    return get_part("forearm")


def test_coverage_counts_taxels_within_the_radius(forearm):
    d = np.linalg.norm(forearm.flat_mm[:, None] - forearm.flat_mm[None], axis=2)
    expected = (d <= placement.AIM_RADIUS_MM).sum(axis=1)
    assert np.array_equal(placement.coverage(forearm), expected)


def test_aims_are_drawn_in_proportion_to_coverage(forearm):
    rng = np.random.default_rng(0)
    draws = np.array([placement.draw_aim_taxel(forearm, rng) for _ in range(20000)])
    w = placement.coverage(forearm)
    low = w < np.median(w)
    expected = w[low].sum() / w.sum()
    assert np.mean(low[draws]) == pytest.approx(expected, abs=0.015)


def test_an_aim_band_keeps_every_aim_inside_it():
    """The default skin aims within `PAPER_AIM_BAND_MM` of the middle of its around coordinate
    and `PAPER_AIM_ALONG_MM` of the middle along the link (closed form on the flat lattice), in
    proportion to coverage there."""
    part = get_part("forearm_paper")
    a, b = part.flat_mm[:, 0], part.flat_mm[:, 1]
    around = np.abs(a - 0.5 * (a.min() + a.max())) <= PAPER_AIM_BAND_MM
    along = np.abs(b - 0.5 * (b.min() + b.max())) <= PAPER_AIM_ALONG_MM
    inside = around & along
    assert 0.2 < around.mean() < 0.5 and 0.1 < along.mean() < 0.3
    rng = np.random.default_rng(0)
    draws = np.array([placement.draw_aim_taxel(part, rng) for _ in range(20000)])
    assert inside[draws].all()
    w = placement.coverage(part) * inside
    low = inside & (w < np.median(w[inside]))
    assert np.mean(low[draws]) == pytest.approx(w[low].sum() / w.sum(), abs=0.015)


def test_hands_and_non_hands_aim_with_the_same_draw(forearm):
    """A non-hand plan leaves the site to the runner, which draws it like a hand plan does; a
    hand plan's palm site stays within a hand-sized distance of its aim."""
    ctx = EpisodeContext(EpisodeConfig(), part=forearm)
    subject = sample_subjects(1, np.random.default_rng(1))[0]
    for seed in range(6):
        _, plan = sample_nonhand(np.random.default_rng(seed))
        assert plan.site_uv is None
        k_runner, _, _ = site_pose(ctx, PressPlan(), np.random.default_rng(seed))
        assert k_runner == placement.draw_aim_taxel(forearm, np.random.default_rng(seed))
        aim = placement.draw_aim_taxel(forearm, np.random.default_rng(seed))
        rng = np.random.default_rng(seed)
        hand = plan_hand_interaction("grasp", "front", subject, forearm, rng)
        reach_mm = 1e3 * max(MAX_GRASP_SHIFT_M, 0.7 * subject.hand.length_m)
        assert np.linalg.norm(np.asarray(hand.site_uv) - forearm.flat_mm[aim]) < reach_mm


def test_plate_edge_is_found_at_its_border():
    plate = get_part("plate")  # 0.2 m square, top face z = 0
    edge = placement.edge_distance_m(
        plate, np.zeros(3), np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), 0.2
    )
    assert edge == pytest.approx(0.1, abs=2 * placement.EDGE_STEP_M)


def test_forearm_edge_matches_the_superellipse_section(forearm):
    """From the top face's centre line towards +y, the normal turns `EDGE_ANGLE_DEG` after the
    arc length of the (tapered) superellipse section at that height (closed form, fine sampling)."""
    shape = ForearmShape()
    z = 0.15
    heights, scales = forearm_profile(shape)
    s = float(np.interp(z, heights, scales))
    theta = np.linspace(0.0, np.pi / 2, 20001)
    pts = superellipse(theta, s * shape.width_m / 2, s * shape.depth_m / 2, shape.squareness)
    half = np.array([s * shape.width_m / 2, s * shape.depth_m / 2])
    n = shape.squareness
    normal = pts ** (n - 1) / half**n  # gradient of |x/a|^n + |y/b|^n (first quadrant)
    angle = np.degrees(np.arctan2(normal[:, 1], normal[:, 0]))
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    expected = arc[np.argmax(angle >= placement.EDGE_ANGLE_DEG)]
    start = np.array([s * shape.width_m / 2, 0.0, z])
    got = placement.edge_distance_m(
        forearm, start, np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), 0.15
    )
    assert got == pytest.approx(expected, abs=2 * placement.EDGE_STEP_M + 0.002)
