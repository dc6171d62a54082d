"""Published measurements of real hands that a set of hand prints can be held against.

Each `Anchor` names a figure of `tactile.prints.figures.anchored_values`, the published range
[low, high] in the figure's unit, how the source states it, and the source. Where a source gives
a mean and a standard deviation the range is mean ± SD; where it gives one estimate without a
spread, the range is stated with the width taken for it and why (``published``).

- Albini & Cannata, IJRR 2020 (the seed paper): 90 volunteers, hand length 15-22 cm (mean 18
  cm), 77.8 % right-handed, 66.7 % male (Table 2, Section 7.2); the palm holds almost 40 % of the
  labelled hand pixels (Fig. 10). The shares of 90 people are held to the 95 % binomial interval
  of a pool of 90 drawn with those shares (± 1.96 sqrt(p (1 - p) / 90)).
- Li ZM, "The influence of wrist position on individual finger forces during forceful grip",
  J Hand Surg Am 27(5):886-896, 2002: maximal grip of an instrumented handle, 9 subjects; the
  four fingers' force sharing, index 32.2 ± 3.8 %, middle 32.6 ± 4.3 %, ring 23.5 ± 4.5 %,
  little 11.7 ± 4.9 % (thumb not measured).
- "Comparison of grip strength among 6 grip methods", J Hand Surg Am 2014, doi
  10.1016/j.jhsa.2014.06.121, 200 healthy men: the thumb contributes an estimated 17 % of grip
  strength (from grip with digits blocked by an orthosis; no spread published).

Not used: Kinoshita et al., Ergonomics 1996 (thumb > 38 % of grip force) measured circular
precision grips of 5-10 cm cylinders lifted from above with the fingertips; a hand grasping a
robot link puts its palm on the link and wraps its fingers round an edge, a power grasp.
"""

from __future__ import annotations

from dataclasses import dataclass

PAPER = "Albini & Cannata, IJRR 2020"
LI_2002 = "Li, J Hand Surg Am 27(5):886-896, 2002"
JHS_2014 = "J Hand Surg Am 2014, doi 10.1016/j.jhsa.2014.06.121"
POOL = 90  # the seed paper's volunteers
LI_LARGEST_SD = 4.9  # percentage points: the widest spread of Li's four finger shares


@dataclass(frozen=True)
class Anchor:
    """A published figure: ``key`` of `anchored_values`, the row's ``label``, the range [low,
    high] (unit of the figure), as the source states it (``published``) and the ``source``."""

    key: str
    label: str
    low: float
    high: float
    published: str
    source: str

    def holds(self, value: float) -> bool:
        """Whether ``value`` lies inside [low, high]."""
        return self.low <= value <= self.high


def _pool_share(key: str, label: str, pct: float, published: str) -> Anchor:
    half = 196 * (pct / 100 * (1 - pct / 100) / POOL) ** 0.5
    return Anchor(key, label, pct - half, pct + half, published, f"{PAPER}, Table 2")


def _li(finger: str, mean: float, sd: float) -> Anchor:
    label = f"grasps: {finger}, % of the four fingers' pressure"
    return Anchor(
        f"grasp.fingers.{finger}", label, mean - sd, mean + sd, f"{mean} ± {sd} %", LI_2002
    )


ANCHORS: tuple[Anchor, ...] = (
    Anchor(
        "hand.pixels.palm",
        "hand prints: palm, % of labelled hand pixels",
        35.0,
        40.0,
        "almost 40 % (read off Fig. 10: 35-40 %)",
        f"{PAPER}, Fig. 10",
    ),
    _li("index", 32.2, 3.8),
    _li("middle", 32.6, 4.3),
    _li("ring", 23.5, 4.5),
    _li("pinkie", 11.7, 4.9),
    Anchor(
        "grasp.digits.thumb",
        "grasps: thumb, % of the five digits' pressure",
        17.0 - LI_LARGEST_SD,
        17.0 + LI_LARGEST_SD,
        f"17 % (estimate, no spread; ± {LI_LARGEST_SD}, Li's widest SD)",
        JHS_2014,
    ),
    Anchor(
        "subjects.length_mean_cm",
        "subjects: hand length, mean (cm)",
        17.5,
        18.5,
        "mean 18 cm (to the cm)",
        f"{PAPER}, Table 2",
    ),
    Anchor("subjects.length_min_cm", "subjects: shortest hand (cm)", 15.0, 22.0, "15-22 cm", PAPER),
    Anchor("subjects.length_max_cm", "subjects: longest hand (cm)", 15.0, 22.0, "15-22 cm", PAPER),
    _pool_share("subjects.right_pct", "subjects: right-handed (%)", 77.8, "77.8 % of 90"),
    _pool_share("subjects.male_pct", "subjects: male (%)", 66.7, "66.7 % of 90"),
)
