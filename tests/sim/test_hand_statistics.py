"""Statistics over 320 generated hand samples (fixed seeds) against published figures.

Albini & Cannata (IJRR 2020): the palm is about 40 % of hand-labelled pixels (Fig. 10); grasps
show several fingers; seven actions from two operator positions plus free touches. A hand print
is no larger than the hand's palmar surface (Rossiter, Chapman & Haywood 1996, "How big is a
hand?", Burns 22: 230-231: palm plus the palmar surface of the digits is 0.7 % of a woman's body
surface area).
"""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest
from scipy.stats import ks_2samp

from sim.contactors.spec import ACTIONS
from sim.contactors.subjects import sample_subjects
from sim.episode.runner import EpisodeContext
from sim.generate.hands import sample_hand
from tactile.dataset.boxes import CONTACT_LEVEL, BoxFolder, box_labels
from tactile.prints.shapes import MIN_BLOB_PX, boxes_of_labels, contact_blobs, part_layout

N_SAMPLES, SEED = 320, 2020
PALM = 6
NAMES = ["palm", "thumb", "index", "middle", "ring", "pinkie"]  # the real folds' class order
PAPER_FRAME_PX = (247, 362)  # rows, columns of the paper's images (../shared/data/real_hands)
GRASPS = (0, 1, 2)  # grasp, grasp + twist cw / ccw


@pytest.fixture(scope="module")
def stats() -> dict:
    ctx = EpisodeContext()
    subjects = sample_subjects(40, np.random.default_rng(SEED))
    rows, rejects = [], Counter()
    for i in range(N_SAMPLES):
        sample, rej = sample_hand(i, SEED, ctx, subjects)
        rejects.update(rej)
        rows.append(sample)
    return {"samples": rows, "rejects": rejects, "active_pa": ctx.cfg.active_pa, "tmap": ctx.tmap}


def real_folds(shared_data) -> list:
    """The real hand prints of both folds, native frame (skip without them)."""
    prints = []
    for fold in ("fold1", "fold2"):
        path = shared_data / "real_hands" / fold
        if not path.is_dir():
            pytest.skip(f"real hand prints not found at {path}")
        folder = BoxFolder.open(path, NAMES, frame_px=PAPER_FRAME_PX)
        prints += [folder[i] for i in range(len(folder))]
    return prints


def marks(image: np.ndarray, boxes: np.ndarray) -> tuple[list[int], int | None]:
    """The areas (px) of a print's blobs and how many of them hold at least `MIN_BLOB_PX` of the
    palm's box-derived pixels (None without a palm box)."""
    blobs = contact_blobs(image, CONTACT_LEVEL, MIN_BLOB_PX)
    areas = np.bincount(blobs.ravel())[1:].tolist()
    if PALM not in boxes[:, 0]:
        return areas, None
    palm = (box_labels(image, boxes) == PALM) & (blobs > 0)
    per_blob = np.bincount(blobs[palm], minlength=blobs.max() + 1)
    return areas, int((per_blob >= MIN_BLOB_PX).sum())


def test_every_action_and_both_operator_positions_occur(stats):
    actions = Counter(int(s["action"]) for s in stats["samples"])
    positions = Counter(int(s["operator_position"]) for s in stats["samples"])
    assert set(actions) == set(range(len(ACTIONS)))
    assert min(actions.values()) >= 0.5 * N_SAMPLES / len(ACTIONS)
    assert {0, 1, 2} <= set(positions)
    for action in range(len(ACTIONS) - 1):  # every paper action from both positions
        seen = {int(s["operator_position"]) for s in stats["samples"] if s["action"] == action}
        assert seen == {0, 1}, ACTIONS[action]


def test_palm_share_of_hand_pixels_is_near_the_papers(stats):
    labels = np.stack([s["label_image"] for s in stats["samples"]])
    share = (labels == PALM).sum() / (labels > 0).sum()
    assert 0.25 <= share <= 0.55


# The palmar surface of the median woman's hand: 0.7 % (Rossiter et al. 1996) of her body surface
# area, 1.72 m² by Du Bois & Du Bois (1916) at the ANSUR II (Gordon et al. 2014) median stature
# 162.6 cm and weight 66.8 kg: 120 cm².
PALMAR_AREA_MM2 = 0.007 * 0.007184 * 162.6**0.725 * 66.8**0.425 * 1e6


def test_median_hand_print_is_smaller_than_a_hand(stats):
    """Active taxels times the skin area per taxel (the map's covered area over its taxels)."""
    tmap = stats["tmap"]
    mm2_per_taxel = tmap.coverage().sum() * tmap.step_mm**2 / tmap.n_taxels
    active = [int((s["pressure_pa"] > stats["active_pa"]).sum()) for s in stats["samples"]]
    assert 0 < np.median(active) * mm2_per_taxel < PALMAR_AREA_MM2


def test_grasps_show_at_least_three_fingers_in_half(stats):
    grasps = [s for s in stats["samples"] if int(s["action"]) in GRASPS]
    fingers = [len(set(np.unique(s["label_image"])) & {1, 2, 3, 4, 5}) for s in grasps]
    assert np.mean(np.array(fingers) >= 3) >= 0.5


def test_a_right_hand_is_drawn_as_the_papers_images_draw_it(stats):
    """The map shows the skin from inside, as the paper's images do (`tactile.geometry.flatten`):
    a right hand's thumb lies right of its fingers (rows down, fingers up), a left hand's left.
    Measured on 307 of 600 hand prints with palm, thumb and a finger boxed: 99.7 % agree."""
    agree = []
    for s in stats["samples"]:
        boxes = boxes_of_labels(s["label_image"], s["image"])
        right = part_layout(boxes)["thumb_right"]
        if np.isfinite(right):
            agree.append((right == 1.0) == (json.loads(s["contactor"])["type"] == "right_hand"))
    assert len(agree) >= 100 and np.mean(agree) >= 0.95, f"{np.mean(agree):.3f} of {len(agree)}"


def test_the_share_of_prints_without_the_palm_is_the_real_one(stats, shared_data):
    """In the real folds 31 % of hand prints have no palm box (fingers and thumb alone: the palm
    held clear of the skin); the generated hand prints lack a palm label as often, within 3
    binomial sd of the two counts (before the digits-alone grips: 2.9 % of 581)."""
    real = []
    for fold in ("fold1", "fold2"):
        path = shared_data / "real_hands" / fold
        if not path.is_dir():
            pytest.skip(f"real hand prints not found at {path}")
        folder = BoxFolder.open(path, ["palm", "thumb", "index", "middle", "ring", "pinkie"])
        real += [PALM not in folder[i].boxes[:, 0] for i in range(len(folder))]
    sim = [not (s["label_image"] == PALM).any() for s in stats["samples"] if s["label_image"].any()]
    p = np.mean(real)
    sd = np.sqrt(p * (1 - p) * (1 / len(real) + 1 / len(sim)))
    assert abs(np.mean(sim) - p) < 3 * sd, f"{np.mean(sim):.3f} of {len(sim)} vs real {p:.3f}"


def test_index_to_little_finger_runs_along_the_columns_as_in_the_real_folds(stats, shared_data):
    """The paper's people stood on one side of the link (`sim.contactors.interactions`,
    ``INDEX_END``): in the real folds index to little finger points along +columns (+-45 deg) in
    71 % of prints; the generated prints as often, within 3 binomial sd (with the operator's side
    drawn at random: 34 %)."""
    real = [part_layout(p.boxes)["little_along"] for p in real_folds(shared_data)]
    sim = [
        part_layout(boxes_of_labels(s["label_image"], s["image"]))["little_along"]
        for s in stats["samples"]
    ]
    real, sim = np.array(real), np.array(sim)
    real, sim = real[np.isfinite(real)], sim[np.isfinite(sim)]
    p = real.mean()
    sd = np.sqrt(p * (1 - p) * (1 / len(real) + 1 / len(sim)))
    assert abs(sim.mean() - p) < 3 * sd, f"{sim.mean():.3f} of {len(sim)} vs real {p:.3f}"


def test_fingers_point_obliquely_along_the_link_as_in_the_real_folds(stats, shared_data):
    """Palm to fingers (`part_layout`'s ``fingers_deg``): the real folds' prints point -37 deg
    [IQR -59, -23] from +rows, the link lying obliquely across the palm; the generated median lies
    inside that IQR (with every grasp from the front across the link: -1 deg, 1,710 prints)."""

    def directions(boxes) -> np.ndarray:
        d = np.array([part_layout(b)["fingers_deg"] for b in boxes])
        return d[np.isfinite(d)]

    real = directions(p.boxes for p in real_folds(shared_data))
    sim = directions(boxes_of_labels(s["label_image"], s["image"]) for s in stats["samples"])
    low, high = np.percentile(real, [25, 75])
    assert low <= np.median(sim) <= high, f"{np.median(sim):.0f} deg, real [{low:.0f}, {high:.0f}]"


@pytest.mark.xfail(
    strict=True,
    reason="every simulated operator stands on one side; 12 % of trials across the link matched "
    "the real share (11.8 %) but moved no real score and turned fewer prints' index-to-little "
    "along the columns (docs/findings.md)",
)
def test_some_people_stand_across_the_link_as_in_the_real_folds(stats, shared_data):
    """Some of the paper's people stood across the link from the others: in the real folds 12 %
    of the prints with palm, thumb and a finger boxed point their fingers more than 120 deg from
    the folds' median direction (the hand turned half a circle); the generated prints should as
    often, within 2 binomial sd (95 %; with every operator on one side 4.8 % of 166, 2.4 sd
    under; with 12 % of trials across 11.8 % of 161)."""

    def turned(directions) -> np.ndarray:
        d = np.array(directions)
        return d[np.isfinite(d)]

    real = turned([part_layout(p.boxes)["fingers_deg"] for p in real_folds(shared_data)])
    sim = turned(
        [
            part_layout(boxes_of_labels(s["label_image"], s["image"]))["fingers_deg"]
            for s in stats["samples"]
        ]
    )
    main = np.median(real)
    away_real, away_sim = (np.abs((d - main + 180.0) % 360.0 - 180.0) > 120.0 for d in (real, sim))
    p = away_real.mean()
    sd = np.sqrt(p * (1 - p) * (1 / len(real) + 1 / len(sim)))
    assert abs(away_sim.mean() - p) < 2 * sd, f"{away_sim.mean():.3f} of {len(sim)} vs real {p:.3f}"


def test_palms_break_into_pads_as_often_as_in_the_real_folds(stats, shared_data):
    """A palm on a link bears on its metacarpal heads, heel and eminences, not over the hollow
    (`sim.contactors.hand`, ``METACARPAL_SHAFT``): in the real folds 66 % of boxed palms lie in
    two or more blobs; the generated ones as often, within 3 binomial sd (with whole metacarpal
    capsules and a flush palm: 21 % of 600)."""
    real = [marks(p.image, p.boxes)[1] for p in real_folds(shared_data)]
    sim = [
        marks(s["image"], boxes_of_labels(s["label_image"], s["image"]))[1]
        for s in stats["samples"]
    ]
    real = np.array([n >= 2 for n in real if n is not None])
    sim = np.array([n >= 2 for n in sim if n is not None])
    p = real.mean()
    sd = np.sqrt(p * (1 - p) * (1 / len(real) + 1 / len(sim)))
    assert abs(sim.mean() - p) < 3 * sd, f"{sim.mean():.3f} of {len(sim)} vs real {p:.3f}"


def test_marks_are_as_large_as_the_real_ones(stats, shared_data):
    """The spread through the skin's cover (`sim.skin.model`, ``spread_sigma_m``) sets how far a
    mark reaches past the pressed pads: the areas of the generated blobs follow the real folds'
    (both on 0.735 mm pixels) within a Kolmogorov-Smirnov distance of 0.12 (measured 0.07-0.09
    on 600 prints; 0.15-0.17 with a 3 mm spread, whose marks fused)."""
    real = [a for p in real_folds(shared_data) for a in marks(p.image, p.boxes)[0]]
    sim = [
        a
        for s in stats["samples"]
        if s["label_image"].any()
        for a in marks(s["image"], boxes_of_labels(s["label_image"], s["image"]))[0]
    ]
    assert ks_2samp(sim, real).statistic < 0.12


def test_the_digits_land_on_the_skin(stats):
    """Each digit is boxed in 93-96 % of the real prints: the paper's people grasped the skin at
    one place along the link (`sim.skin.parts.PAPER_AIM_ALONG_MM`). Each digit shows in at least
    68 % of the generated hand prints, 3 binomial sd under the thumb's 77 % (the rarest, default
    set); aimed anywhere along the skin the thumb showed in 61 %, fingers near either end ran off
    it."""
    shown = np.array(
        [
            [(s["label_image"] == k).sum() >= MIN_BLOB_PX for k in range(1, 6)]
            for s in stats["samples"]
            if s["label_image"].any()
        ]
    )
    assert (shown.mean(axis=0) >= 0.68).all(), shown.mean(axis=0).round(3)


def test_rejects_are_rare_and_named(stats):
    total = sum(stats["rejects"].values())
    assert set(stats["rejects"]) <= {"warning", "nan", "too_deep", "no_contact"}
    assert total < 0.1 * N_SAMPLES
