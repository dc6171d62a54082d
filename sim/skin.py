"""The skin model: penetration depth at each taxel -> pressure -> 16-bit reading.

Pure functions on arrays plus a frozen `SkinConfig` (units and the reason for each default) and a
`SkinInstance` holding the per-taxel draws (gain, baseline, drift) of one physical skin. The
noise-free ground truth (`SkinFrame.pressure_pa`) is kept beside the noisy reading.

Chain, per frame: depth d (m) -> elastic foundation p = k · d_ref · (d / d_ref)^n (Pa) -> spread
through the dielectric/fabric layer (Gaussian kernel over taxel distance, rows normalised so that
a uniform pressure stays uniform) -> counts = baseline + drift · t + gain · counts_per_pa · p +
noise -> round, clip to [0, 65535].
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

from tactile.errors import ConfigError
from tactile.faults import dead_modules

FULL_SCALE_COUNTS = 65535  # 16-bit capacitance-to-digital converter (AD7147 in Schmitz et al. 2011)


@dataclass(frozen=True)
class SkinConfig:
    """Parameters of the capacitive skin model (SI units; counts are ADC least significant bits)."""

    # Winkler foundation modulus E/h: soft silicone dielectric, E ≈ 0.2 MPa (assumed, soft foams
    # span 0.1–0.5 MPa) over h ≈ 2 mm (the dielectric of Schmitz et al. 2011) -> 1e8 Pa/m.
    stiffness_pa_per_m: float = 1.0e8
    # Exponent n of p = k·d_ref·(d/d_ref)^n; 1 = linear elastic foundation (foams stiffen, n > 1).
    exponent: float = 1.0
    # Depth at which the power law equals the linear law (m); the dielectric thickness.
    reference_depth_m: float = 2.0e-3
    # Gaussian sigma of the spread through the layer (m): sqrt(h² + r_pad²) for the 2 mm
    # dielectric and the 1.75 mm pad radius ≈ 2.7 mm, rounded to 3 mm; a neighbour at the 8 mm
    # pitch gets exp(-64/18) ≈ 3 % of the weight, a centre pad keeps ≈ 84 % of a point load.
    spread_sigma_m: float = 3.0e-3
    # Kernel truncation radius in sigmas.
    spread_cutoff_sigmas: float = 3.0
    # Pressure at which the nominal reading reaches full scale from the mean baseline (Pa): an
    # assumed 100 kPa, the order of firm human touch (10–100 kPa), so strong presses saturate.
    full_scale_pa: float = 1.0e5
    # Relative std of the per-taxel gain (dielectric thickness and pad area spread), assumed 10 %.
    gain_spread: float = 0.10
    # Mean untouched reading (counts): leaves room for negative noise and drift below it.
    baseline_counts: float = 4000.0
    # Std of the untouched reading across taxels (counts).
    baseline_spread_counts: float = 500.0
    # Std across taxels of the baseline drift rate (counts/s); thermal drift is slow, minutes.
    drift_std_counts_per_s: float = 2.0
    # Std of the white read noise per frame (counts): ≈ 0.15 % of full scale, ~0.4 LSB of the
    # 8-bit values the iCub skin driver reports (assumed).
    noise_std_counts: float = 100.0

    def __post_init__(self) -> None:
        for f in fields(self):
            value = getattr(self, f.name)
            if not np.isfinite(value) or value < 0:
                raise ConfigError(f"SkinConfig.{f.name} = {value!r}; must be finite and >= 0")
        for name in ("stiffness_pa_per_m", "exponent", "reference_depth_m", "full_scale_pa"):
            if getattr(self, name) == 0:
                raise ConfigError(f"SkinConfig.{name} must be > 0; got 0")
        if self.baseline_counts >= FULL_SCALE_COUNTS:
            raise ConfigError(f"SkinConfig.baseline_counts must be < {FULL_SCALE_COUNTS}")

    @property
    def counts_per_pa(self) -> float:
        """Nominal gain (counts/Pa): full scale minus mean baseline over `full_scale_pa`."""
        return (FULL_SCALE_COUNTS - self.baseline_counts) / self.full_scale_pa


def depth_to_pressure(depth_m: np.ndarray, cfg: SkinConfig) -> np.ndarray:
    """Elastic-foundation pressure p = k · d_ref · (d / d_ref)^n.

    depth_m : (..., N) float, m, >= 0 (negative treated as 0). Returns (..., N) float, Pa.
    """
    d = np.maximum(np.asarray(depth_m, dtype=np.float64), 0.0)
    if cfg.exponent == 1.0:
        return cfg.stiffness_pa_per_m * d
    ref = cfg.reference_depth_m
    return cfg.stiffness_pa_per_m * ref * (d / ref) ** cfg.exponent


def spread_matrix(
    positions_m: np.ndarray, sigma_m: float, cutoff_sigmas: float = 3.0
) -> csr_matrix:
    """Row-normalised Gaussian kernel between taxels: reading_i = sum_j W_ij · p_j.

    positions_m : (N, 3) float, m. Returns (N, N) sparse float. sigma_m = 0 gives the identity.
    Rows sum to 1, so a uniform pressure field is read unchanged.
    """
    n = positions_m.shape[0]
    if sigma_m <= 0:
        return csr_matrix((np.ones(n), (np.arange(n), np.arange(n))), shape=(n, n))
    pairs = cKDTree(positions_m).query_pairs(cutoff_sigmas * sigma_m, output_type="ndarray")
    rows = np.concatenate([np.arange(n), pairs[:, 0], pairs[:, 1]])
    cols = np.concatenate([np.arange(n), pairs[:, 1], pairs[:, 0]])
    dist2 = np.sum((positions_m[rows] - positions_m[cols]) ** 2, axis=1)
    w = np.exp(-0.5 * dist2 / sigma_m**2)
    mat = csr_matrix((w, (rows, cols)), shape=(n, n))
    return csr_matrix(mat.multiply(1.0 / np.asarray(mat.sum(axis=1))))


def quantize(counts: np.ndarray) -> np.ndarray:
    """Round to the nearest count and saturate to [0, 65535]. (..., N) float -> uint16."""
    return np.clip(np.rint(counts), 0, FULL_SCALE_COUNTS).astype(np.uint16)


@dataclass(frozen=True)
class SkinFrame:
    """One frame of the skin: noise-free truth beside the raw reading.

    depth_m : (N,) float, m — penetration depth from the simulator.
    pressure_pa : (N,) float, Pa — noise-free pressure sensed by each taxel (after spreading).
    reading : (N,) uint16, counts — raw 16-bit reading (gain, baseline, drift, noise, saturation).
    signal_counts : (N,) float, counts — reading minus the taxel's known baseline and drift.
    """

    depth_m: np.ndarray
    pressure_pa: np.ndarray
    reading: np.ndarray
    signal_counts: np.ndarray


@dataclass(frozen=True, eq=False)
class SkinInstance:
    """One physical skin: the config, the spread kernel and the per-taxel draws.

    gain : (N,) float, relative (mean 1). baseline_counts, drift_counts_per_s : (N,) float.
    dead : (N,) bool — taxels that read only their baseline (faults from `tactile.faults`).
    """

    cfg: SkinConfig
    spread: csr_matrix
    gain: np.ndarray
    baseline_counts: np.ndarray
    drift_counts_per_s: np.ndarray
    dead: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))

    @classmethod
    def create(
        cls, positions_m: np.ndarray, cfg: SkinConfig, rng: np.random.Generator
    ) -> SkinInstance:
        """Draw the per-taxel gain, baseline and drift rate for taxels at positions_m (N, 3), m."""
        n = positions_m.shape[0]
        gain = np.maximum(rng.normal(1.0, cfg.gain_spread, n), 0.05)
        base = rng.normal(cfg.baseline_counts, cfg.baseline_spread_counts, n)
        drift = rng.normal(0.0, cfg.drift_std_counts_per_s, n)
        spread = spread_matrix(positions_m, cfg.spread_sigma_m, cfg.spread_cutoff_sigmas)
        return cls(cfg, spread, gain, base, drift, np.zeros(n, dtype=bool))

    def with_dead_modules(
        self, module_ids: np.ndarray, n: int, rng: np.random.Generator
    ) -> SkinInstance:
        """A copy where n random whole modules (module_ids (N,)) are dead."""
        return replace(self, dead=self.dead | dead_modules(module_ids, n, rng))

    @property
    def n_taxels(self) -> int:
        return int(self.gain.shape[0])

    def pressure(self, depth_m: np.ndarray) -> np.ndarray:
        """Noise-free sensed pressure (N,) Pa from depth (N,) m: foundation law, then spread."""
        return self.spread @ depth_to_pressure(depth_m, self.cfg)

    def offset(self, time_s: float) -> np.ndarray:
        """Untouched reading (N,) counts at time_s: baseline plus linear drift."""
        return self.baseline_counts + self.drift_counts_per_s * time_s

    def frame(
        self, depth_m: np.ndarray, rng: np.random.Generator | None, time_s: float = 0.0
    ) -> SkinFrame:
        """Depth (N,) m -> `SkinFrame`. rng=None gives the noise-free reading."""
        if np.shape(depth_m) != (self.n_taxels,):
            raise ConfigError(f"depth has shape {np.shape(depth_m)}; expected ({self.n_taxels},)")
        pressure = self.pressure(depth_m)
        offset = self.offset(time_s)
        gain = np.where(self.dead, 0.0, self.gain) if self.dead.size else self.gain
        counts = offset + gain * self.cfg.counts_per_pa * pressure
        if rng is not None and self.cfg.noise_std_counts > 0:
            counts = counts + rng.normal(0.0, self.cfg.noise_std_counts, self.n_taxels)
        reading = quantize(counts)
        return SkinFrame(np.asarray(depth_m), pressure, reading, reading - offset)
