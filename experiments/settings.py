"""What the robustness experiments run (torch-free): the Test A grid, the Test B shares, the
test subsets, how networks not given are trained, and the faults of fault-aware training.

    scale = dataclasses.replace(QUICK, n_patterns=3)      # robustness-a --quick --patterns 3
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from tactile.errors import ConfigError

N_SPOTS = (1, 2, 3, 4)  # Test A: blind spots per pattern (paper)
RADII_MM = (10.0, 20.0, 30.0, 40.0)  # Test A: spot radius, mm (paper)
FRACTIONS = (0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7)  # Test B: share of taxels removed (paper)
SEG_ARCHS = ("segnet", "fcn16s")


@dataclass(frozen=True)
class TrainPlan:
    """How a network missing from the command line is trained: the arch's preset
    (``learn.config``) with these changes, on the train split of the dataset.

    epochs : None = the preset's. n_train, seg_n_train : train samples of the classifier and
    of the segmenter, seeded subsets (None: all). flips : the paper's threefold flips.
    seg_width : the segmenter's channel multiplier and input_size : (h, w) px (None: preset).
    suffix : appended to the model folder's name, so plans never reuse each other's networks.
    device : where they train ("cpu", "cuda", "cuda:N"); a trained network is reused wherever
    it trained.
    """

    epochs: int | None = None
    n_train: int | None = None
    seg_n_train: int | None = None
    flips: bool = True
    seg_width: float | None = None
    input_size: tuple[int, int] | None = None
    suffix: str = ""
    device: str = "cpu"

    def __post_init__(self) -> None:
        if self.epochs is not None and self.epochs < 1:
            raise ConfigError(f"TrainPlan.epochs {self.epochs} is out of range; allowed >= 1")
        if min(n for n in (self.n_train, self.seg_n_train, 2) if n is not None) < 2:
            raise ConfigError(f"training samples {self.n_train}, {self.seg_n_train}: give >= 2")

    def samples(self, arch: str) -> int | None:
        """Train samples used for ``arch`` (None: all)."""
        return self.seg_n_train if arch in SEG_ARCHS else self.n_train


#: The presets' first 2 epochs: HandsNet on the whole train part, SegNet on 600 samples.
QUICK_PLAN = TrainPlan(epochs=2, seg_n_train=600, suffix="_quick")


@dataclass(frozen=True)
class Scale:
    """Sizes of a robustness run.

    n_patterns : random patterns per condition. n_classify : test samples classified, a
    seeded subset (None: all). n_segment : test hand samples segmented, a seeded subset
    (0: no segmentation). n_spots, radii_mm : the Test A grid (count, mm). fractions : the
    Test B shares of taxels removed (0 = the intact map). plan : how networks not given train.
    """

    n_patterns: int
    n_classify: int | None
    n_segment: int
    n_spots: tuple[int, ...] = N_SPOTS
    radii_mm: tuple[float, ...] = RADII_MM
    fractions: tuple[float, ...] = FRACTIONS
    plan: TrainPlan = field(default_factory=TrainPlan)

    def __post_init__(self) -> None:
        if self.n_patterns < 1:
            raise ConfigError(f"--patterns {self.n_patterns} is out of range; allowed >= 1")
        if (self.n_classify is not None and self.n_classify < 1) or self.n_segment < 0:
            raise ConfigError(f"test samples {self.n_classify}, {self.n_segment}: give >= 1")
        if min(self.n_spots) < 0 or min(self.radii_mm) < 0:
            raise ConfigError("blind spots: counts and radii (mm) must be >= 0")
        if not all(0.0 <= f < 1.0 for f in self.fractions):
            raise ConfigError(f"removed shares must lie in [0, 1), got {self.fractions}")


FULL = Scale(n_patterns=10, n_classify=None, n_segment=200)
QUICK = Scale(n_patterns=2, n_classify=300, n_segment=40, plan=QUICK_PLAN)


def changed(scale: Scale, patterns: int | None, segmentation: bool, device: str) -> Scale:
    """``scale`` as the command line changes it: ``--patterns`` (None: kept),
    ``--no-segmentation`` (no segmented samples) and the training ``--device``."""
    n_patterns = scale.n_patterns if patterns is None else patterns
    plan = dataclasses.replace(scale.plan, device=device)
    n_segment = scale.n_segment if segmentation else 0
    return dataclasses.replace(scale, n_patterns=n_patterns, n_segment=n_segment, plan=plan)


@dataclass(frozen=True)
class FaultMix:
    """The random faults of one fault-aware training copy (each drawn independently).

    p_blind : probability of blind spots; n_spots : (min, max) count; radius_mm : (min, max) mm.
    p_dead : probability of dead modules; dead_modules : (min, max) count (needs module ids).
    p_drift : probability of gain drift; gain_sigma : sd of the log gain (dimensionless).
    p_removal : probability of a map with taxels removed; fractions : shares removed in the
    pool of such maps; pool_patterns : nested removal patterns in the pool (each at every share).
    """

    p_blind: float = 0.5
    n_spots: tuple[int, int] = (1, 4)
    radius_mm: tuple[float, float] = (10.0, 40.0)
    p_dead: float = 0.25
    dead_modules: tuple[int, int] = (1, 3)
    p_drift: float = 0.5
    gain_sigma: float = 0.2
    p_removal: float = 0.5
    fractions: tuple[float, ...] = FRACTIONS[1:]
    pool_patterns: int = 2

    def __post_init__(self) -> None:
        probs = (self.p_blind, self.p_dead, self.p_drift, self.p_removal)
        if not all(0.0 <= p <= 1.0 for p in probs):
            raise ConfigError(f"FaultMix probabilities must lie in [0, 1], got {probs}")
        if not all(0.0 < f < 1.0 for f in self.fractions) or self.pool_patterns < 1:
            raise ConfigError("FaultMix.fractions must lie in (0, 1), pool_patterns >= 1")
