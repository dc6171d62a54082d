"""The simulated hands against published measurements of real hands (fixed seeds).

- Albini & Cannata, IJRR 2020 (Table 2, Section 7.2): 90 volunteers, hand length 15-22 cm (mean
  18 cm), 77.8 % right-handed, 66.7 % male.
- Li, J Hand Surg Am 27(5):886-896, 2002: force sharing of the four fingers in maximal grip,
  index 32.2 ± 3.8 %, middle 32.6 ± 4.3 %, ring 23.5 ± 4.5 %, little 11.7 ± 4.9 % (mean ± SD).
- J Hand Surg Am 2014, doi 10.1016/j.jhsa.2014.06.121: the thumb gives an estimated 17 % of grip
  strength (no spread published; held to ± 4.9 points, Li's widest SD; `tactile.prints.anchors`).
- Cylinder grips load the fingertips most (Kargov et al., J Med Eng Technol 30(3), 2006: the
  highest forces at the fingertips and the thumb); pushing loads the palm most (pressure mapping
  of a pushed cylinder, Work 2007: the thenar region carries the most force).

The forces are MuJoCo's contact forces of each hand part on the link at the end of the hold of
240 grasps and as many pushes (about a minute, marked slow), summed over the presses (shares of
sums, as force-sharing studies report them). The sample is sized so that the figure's seed-to-seed
spread (about ± 2 points for a share, measured over seeds 0 and 5) stays inside the published
range's half-width.
"""

from __future__ import annotations

import re

import mujoco
import numpy as np
import pytest

from sim.contactors.subjects import sample_subjects
from sim.episode.runner import FRAME_DT_S, EpisodeContext, episode_rng
from sim.generate.hands import hand_maker
from sim.view.scenes import replay_geoms
from tactile.prints.anchors import ANCHORS

SEED = 11
PARTS = ("thumb", "index", "middle", "ring", "pinkie", "palm")
_PART = re.compile(r"[rl]h_(thumb|index|middle|ring|pinkie|palm)_(\w+)$")
ANCHOR = {a.key: a for a in ANCHORS}


def part_forces(ctx: EpisodeContext, contactor, scene) -> tuple[np.ndarray, dict[str, float]]:
    """(6,) N normal contact force of each hand part on the link (order `PARTS`), and the
    fingers' force by phalanx (proximal, middle, distal), N."""
    m, d = scene.model, scene.data
    force, parts, segments = (
        np.zeros(6),
        np.zeros(6),
        {"proximal": 0.0, "middle": 0.0, "distal": 0.0},
    )
    for k in range(d.ncon):
        c = d.contact[k]
        mujoco.mj_contactForce(m, d, k, force)
        for g in (c.geom1, c.geom2):
            match = _PART.search(m.geom(g).name)
            if match and m.geom_contype[g]:
                parts[PARTS.index(match.group(1))] += force[0]
                if match.group(1) not in ("palm", "thumb"):
                    segments[match.group(2)] += force[0]
    return parts, segments


def pressed(action: str, n: int) -> tuple[np.ndarray, dict[str, float]]:
    """Summed part forces (N) and finger-segment forces (N) of ``n`` presses of ``action``."""
    ctx = EpisodeContext()
    subjects = sample_subjects(90, np.random.default_rng(SEED))
    total, segments = np.zeros(6), {"proximal": 0.0, "middle": 0.0, "distal": 0.0}
    for i in range(n):
        rng, _ = episode_rng(SEED, i, 0)
        contactor, plan = hand_maker(subjects, ctx, action)(rng)
        end_of_hold = round(sum(plan.durations_s[:3]) / FRAME_DT_S) - 1
        replay_geoms(ctx, contactor, plan, rng, end_of_hold)
        parts, segs = part_forces(ctx, contactor, ctx.scene(contactor))
        total += parts
        segments = {k: segments[k] + segs[k] for k in segments}
    return total, segments


@pytest.fixture(scope="module")
def grasps():
    return pressed("grasp", 240)


@pytest.mark.slow
@pytest.mark.parametrize("finger", ["index", "middle", "ring", "pinkie"])
def test_grasp_force_sharing_of_the_four_fingers_is_li_2002(grasps, finger):
    force = grasps[0]
    share = 100 * force[PARTS.index(finger)] / force[1:5].sum()
    anchor = ANCHOR[f"grasp.fingers.{finger}"]
    assert anchor.low <= share <= anchor.high, f"{finger}: {share:.1f} %"


@pytest.mark.slow
def test_grasp_thumb_share_is_the_estimate_of_jhs_2014(grasps):
    force = grasps[0]
    share = 100 * force[0] / force[:5].sum()
    anchor = ANCHOR["grasp.digits.thumb"]
    assert anchor.low <= share <= anchor.high, f"thumb: {share:.1f} %"


@pytest.mark.slow
def test_grasps_load_the_fingertips_and_pushes_the_palm(grasps):
    _, segments = grasps
    assert segments["distal"] > segments["proximal"] > segments["middle"]
    # the palm carries most of a push; over 80 pushes its share moved 5 points with the draws
    push, _ = pressed("push_away", 240)
    assert push[5] > 0.5 * push.sum(), f"palm: {100 * push[5] / push.sum():.1f} %"


def test_the_subject_pool_is_the_papers():
    subjects = sample_subjects(90, np.random.default_rng(SEED))
    length_cm = 100 * np.array([s.hand.length_m for s in subjects])
    right = 100 * np.mean([s.handedness == "right" for s in subjects])
    male = 100 * np.mean([s.sex == "male" for s in subjects])
    assert right == pytest.approx(77.8, abs=0.1) and male == pytest.approx(66.7, abs=0.1)
    for key, value in (
        ("subjects.length_mean_cm", length_cm.mean()),
        ("subjects.length_min_cm", length_cm.min()),
        ("subjects.length_max_cm", length_cm.max()),
        ("subjects.right_pct", right),
        ("subjects.male_pct", male),
    ):
        assert ANCHOR[key].holds(value), f"{key}: {value:.2f}"
