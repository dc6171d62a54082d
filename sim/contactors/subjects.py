"""Simulated subjects: a hand (size, handedness, tissue softness), sex, and habits (force, noise).

Population after Albini & Cannata, IJRR 2020 (Table 2, Section 7.2): 90 volunteers, hand length
15-22 cm (mean 18 cm), 77.8 % right-handed (70 of 90), 66.7 % male (60 of 90). A pool holds
those shares exactly (rounded to whole people), in random order. Sex sets the hand's size: the
ANSUR-type means of `sim.contactors.hand_kinematics` (men 19.3 cm long, 8.9 cm broad; women 17.7 and
7.8 cm) give women's hands 0.917 of men's length and breadth / length ratios of 0.461 and 0.441; the
two means are scaled so that the pool's mean is the paper's 18 cm (men 18.5, women 17.0 cm), and the
spread within a sex (1.3 cm) keeps the pool's spread at the 1.5 cm that puts 15-22 cm at about
-2 and +2.7 sd. Force habits do not depend on sex: the paper reports no press forces, and maximal
grip strength says little about how hard people choose to touch a robot. Subjects carry ids, so
a dataset can be split by subject and its test set hold hands never seen in training
(`split_subjects`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sim.contactors.hand import HAND_LENGTH_RANGE_M, HandConfig
from tactile.errors import ConfigError

MEAN_HAND_LENGTH_M = 0.18  # Albini & Cannata 2020
SD_HAND_LENGTH_M = 0.015  # the pool's spread: 15-22 cm over 90 people is about +-2.3 sd
RIGHT_HANDED_FRACTION = 0.778  # Albini & Cannata 2020: 70 of 90
MALE_FRACTION = 0.667  # Albini & Cannata 2020: 60 of 90
SEXES: tuple[str, ...] = ("male", "female")
FEMALE_LENGTH_RATIO = 17.7 / 19.3  # women's / men's mean hand length (ANSUR-type means)
BREADTH_RATIO_BY_SEX = {"male": 8.9 / 19.3, "female": 7.8 / 17.7}  # breadth / length means
BREADTH_RATIO_SD = 0.015
TISSUE_DEPTH_MEAN_M, TISSUE_DEPTH_SD_M = 0.0035, 0.0004  # soft-tissue allowance (m)
FORCE_LOG_SD = 0.3  # force scale is log-normal around 1 (people press 0.5-2x as hard)
APPROACH_SD_DEG = 15.0  # preferred offset of the approach direction around the link axis
POSE_NOISE_RANGE_DEG = (2.0, 8.0)  # per-subject std of joint-angle noise on grasp poses
# Habitual finger spread: the angle (degrees) between neighbouring fingers of a hand that meets a
# link, at the MCP joints: index and ring lean that far from the middle finger, the pinkie twice
# as far, within the MCP's 20 degrees of abduction (`sim.contactors.interaction_poses.
# finger_spread`). Uniform 16-20 degrees, the hand opened to its limit: in the real prints the
# fingertips leave marks of their own (0.60 [IQR 0.40, 1.00] of a print's fingers) and the boxes
# of neighbouring fingers lie 44 mm [40, 51] apart, index and little 120 mm [106, 133]
# (`handskin stats`, 342 prints of ../shared/data/real_hands fold 1). Measured on the default
# forearm (600 hand prints, seed 1, with the phalanx pads of `sim.contactors.hand.PAD_SPAN`):
# 8-16 deg (was) 32 and 81 mm, fingers with a mark of their own 0.33; 16-20 deg 34 and 85 mm,
# 0.40. People open the hand wider for larger objects (Santello et al., J Neurosci 18(23),
# 1998), and a robot link is larger than any handle.
FINGER_SPREAD_RANGE_DEG = (16.0, 20.0)
FORCE_SCALE_RANGE = (0.2, 5.0)
APPROACH_RANGE_DEG = (-60.0, 60.0)
POSE_NOISE_LIMIT_DEG = (0.0, 30.0)
FINGER_SPREAD_LIMIT_DEG = (0.0, 20.0)  # index and ring up to their MCP's 20 deg of abduction


@dataclass(frozen=True)
class Subject:
    """One simulated person: their (dominant) hand and their habits."""

    subject_id: str  # unique id, e.g. "s0007"
    hand: HandConfig  # size, side = handedness, tissue softness
    force_scale: float = 1.0  # multiplier on an interaction's nominal force (dimensionless)
    approach_deg: float = 0.0  # preferred approach azimuth around the link axis, degrees
    pose_noise_deg: float = 4.0  # std of per-joint noise added to grasp poses, degrees
    # habitual angle between neighbouring fingers (MCP abduction), degrees; 0 = fingers together
    finger_spread_deg: float = 0.0
    sex: str = "male"  # "male" or "female" (sets the hand's size in `sample_subjects`)

    def __post_init__(self) -> None:
        if not self.subject_id:
            raise ConfigError("Subject.subject_id is empty; give a unique id such as 's0001'")
        if self.sex not in SEXES:
            raise ConfigError(f"Subject.sex={self.sex!r} unknown; choose one of {SEXES}")
        _check("force_scale", self.force_scale, FORCE_SCALE_RANGE)
        _check("approach_deg", self.approach_deg, APPROACH_RANGE_DEG)
        _check("pose_noise_deg", self.pose_noise_deg, POSE_NOISE_LIMIT_DEG)
        _check("finger_spread_deg", self.finger_spread_deg, FINGER_SPREAD_LIMIT_DEG)

    @property
    def handedness(self) -> str:
        """ "right" or "left": the side of the dominant hand used in the interactions."""
        return self.hand.side

    @property
    def tissue_depth_m(self) -> float:
        """Soft-tissue allowance of this subject's hand, metres (larger = softer)."""
        return self.hand.tissue_depth_m


def _check(field: str, value: float, bounds: tuple[float, float]) -> None:
    lo, hi = bounds
    if not np.isfinite(value) or not lo <= value <= hi:
        raise ConfigError(f"Subject.{field}={value!r} out of range; allowed [{lo:g}, {hi:g}]")


def truncated_normal(
    rng: np.random.Generator, n: int, mean: float, sd: float, bounds: tuple[float, float]
) -> np.ndarray:
    """(n,) draws of N(mean, sd) restricted to ``bounds`` (rejection sampling, deterministic)."""
    out = np.empty(0)
    while out.size < n:
        draw = rng.normal(mean, sd, size=2 * (n - out.size) + 8)
        out = np.concatenate([out, draw[(draw >= bounds[0]) & (draw <= bounds[1])]])
    return out[:n]


def sex_mean_lengths_m() -> dict[str, float]:
    """Mean hand length (m) of each sex: the ANSUR-type ratio, scaled to the paper's pool mean."""
    male = MEAN_HAND_LENGTH_M / (MALE_FRACTION + (1 - MALE_FRACTION) * FEMALE_LENGTH_RATIO)
    return {"male": male, "female": FEMALE_LENGTH_RATIO * male}


def exact_share(n: int, fraction: float, rng: np.random.Generator) -> np.ndarray:
    """(n,) bool: round(fraction · n) True values in random order (a pool with the share)."""
    out = np.zeros(n, dtype=bool)
    out[rng.permutation(n)[: round(fraction * n)]] = True
    return out


def sample_subjects(n: int, rng: np.random.Generator, *, first_id: int = 0) -> list[Subject]:
    """``n`` subjects drawn from the paper's population; ids ``s{first_id:04d}`` onwards.

    Exactly round(0.667 n) men and round(0.778 n) right-handed people, in random order. Hand
    length: normal around the sex's mean (`sex_mean_lengths_m`), sd `within_sex_sd_m`, truncated
    to 15-22 cm; breadth = length x N(the sex's ratio, 0.015); habitual finger spread uniform
    over `FINGER_SPREAD_RANGE_DEG`. The same Generator state gives the same subjects.
    """
    if n < 0:
        raise ConfigError(f"sample_subjects: n={n} out of range; allowed n >= 0")
    male = exact_share(n, MALE_FRACTION, rng)
    right = exact_share(n, RIGHT_HANDED_FRACTION, rng)
    sex = np.where(male, "male", "female")
    means, sd = sex_mean_lengths_m(), within_sex_sd_m()
    length = np.empty(n)
    for s in SEXES:
        pick = sex == s
        length[pick] = truncated_normal(rng, int(pick.sum()), means[s], sd, HAND_LENGTH_RANGE_M)
    ratio_mean = np.array([BREADTH_RATIO_BY_SEX[s] for s in sex])
    ratio = np.clip(rng.normal(ratio_mean, BREADTH_RATIO_SD), 0.40, 0.50)
    tissue = np.clip(rng.normal(TISSUE_DEPTH_MEAN_M, TISSUE_DEPTH_SD_M, n), 0.0025, 0.0045)
    force = np.clip(np.exp(rng.normal(0.0, FORCE_LOG_SD, n)), 0.4, 2.5)
    approach = np.clip(rng.normal(0.0, APPROACH_SD_DEG, n), -45.0, 45.0)
    noise = rng.uniform(*POSE_NOISE_RANGE_DEG, n)
    spread = rng.uniform(*FINGER_SPREAD_RANGE_DEG, n)
    return [
        Subject(
            subject_id=f"s{first_id + i:04d}",
            hand=HandConfig(
                length_m=float(length[i]),
                breadth_m=float(length[i] * ratio[i]),
                side="right" if right[i] else "left",
                tissue_depth_m=float(tissue[i]),
            ),
            force_scale=float(force[i]),
            approach_deg=float(approach[i]),
            pose_noise_deg=float(noise[i]),
            finger_spread_deg=float(spread[i]),
            sex=str(sex[i]),
        )
        for i in range(n)
    ]


def within_sex_sd_m() -> float:
    """Spread (m) of hand length within a sex that keeps the pool's at `SD_HAND_LENGTH_M`: the
    pool's variance less the variance between the two sexes' means."""
    means = sex_mean_lengths_m()
    between = MALE_FRACTION * (1 - MALE_FRACTION) * (means["male"] - means["female"]) ** 2
    return float(np.sqrt(SD_HAND_LENGTH_M**2 - between))


def split_subjects(
    subjects: list[Subject], test_fraction: float, rng: np.random.Generator
) -> tuple[list[Subject], list[Subject]]:
    """Split subjects (not samples) into (train, test); no subject id is in both."""
    if not 0.0 <= test_fraction <= 1.0:
        raise ConfigError(f"split_subjects: test_fraction={test_fraction} outside [0, 1]")
    ids = [s.subject_id for s in subjects]
    if len(set(ids)) != len(ids):
        raise ConfigError("split_subjects: duplicate subject ids; sample with distinct first_id")
    order = rng.permutation(len(subjects))
    n_test = round(test_fraction * len(subjects))
    test = {int(i) for i in order[:n_test]}
    train_list = [s for i, s in enumerate(subjects) if i not in test]
    return train_list, [s for i, s in enumerate(subjects) if i in test]
