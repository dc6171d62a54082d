"""The skin model: penetration depth at each taxel -> pressure -> 16-bit reading.

Pure functions on arrays plus a frozen `SkinConfig` (units and the reason for each default) and a
`SkinInstance` holding the per-taxel draws (gain, baseline, drift) of one physical skin. The
noise-free ground truth (`SkinFrame.pressure_pa`) is kept beside the noisy reading.

Chain, per frame: depth d (m) -> elastic foundation p = k · d_ref · (d / d_ref)^n (Pa) ->
force-consistent scaling (below) -> spread through the dielectric/fabric layer (Gaussian kernel
over taxel distance, rows normalised so that a uniform pressure stays uniform) -> counts =
baseline + drift · t + gain · counts_per_pa · s(p) + noise -> round, clip to [0, 65535], where
s(p) = p_sat · (1 - exp(-p / p_sat)) is the pad's saturating response (`saturate`).

Saturation. The grey levels of real prints (../shared/data/real_hands, floor(255 K / max K) of
the raw readings K) put most of a print's marks near its brightest: median blob peak 196 of 255,
contact pixels' grey levels 17 / 35 / 74 / 133 / 188 at the 10th/25th/50th/75th/90th
percentiles (fold 1), where a linear pad gave the default set's hand prints 9 / 19 / 45 / 90 /
139. A soft dielectric's compression levels off as it densifies, so light pads read relatively
brighter beside a hard press. With no published response curve of the paper's skin, p_sat is
fitted: the two-sample Kolmogorov-Smirnov distance between the contact grey levels of 600
simulated hand prints (default forearm, seed 1) and real fold 1 / fold 2 is 0.177 / 0.173
linear, 0.081 / 0.087 at 3 kPa, 0.051 / 0.057 at 4, 0.042 / 0.042 at 5 (14 / 32 / 77 / 139 /
187), 0.062 / 0.061 at 7, 0.076 / 0.075 at 9 kPa.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

from tactile.dataset.readout import NOISE_FLOOR_SIGMAS, Readout
from tactile.errors import ConfigError
from tactile.images.faults import dead_modules

FULL_SCALE_COUNTS = 65535  # 16-bit capacitance-to-digital converter (AD7147 in Schmitz et al. 2011)
SATURATION_PA = 5.0e3  # `SkinConfig.saturation_pa`, fitted to real prints (module docstring)


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
    # Gaussian sigma of the spread through the layer (m), fitted to the real prints' mark sizes:
    # Kolmogorov-Smirnov distance between the areas of the blobs of 600 simulated hand prints
    # (default skin, 5.9 mm pitch, seed 1) and of real fold 1 / fold 2 (../shared/data/real_hands)
    # 0.107 / 0.101 at 0, 0.098 / 0.087 at 1.5, 0.090 / 0.088 at 2, 0.105 / 0.111 at 2.5,
    # 0.152 / 0.169 at 3 mm (sqrt(h² + r_pad²) for the 2 mm dielectric and 1.75 mm pads): at 3 mm
    # a neighbour 5.9 mm away took 14 % of a pad's load and fingers' marks fused (a finger's box
    # 33-35 x 33 mm, at 2 mm 29-32 x 29; real 25-26 x 23-24). At 2 mm it takes 1.3 %; 8 mm: 0.03 %.
    spread_sigma_m: float = 2.0e-3
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
    # Scale each frame's foundation field so that sum(p · taxel area) equals the solver's normal
    # force on the sensorized region (module docstring); False: pure elastic foundation p = k · d.
    force_consistent: bool = True
    # Saturation of the reading (Pa): a pad reads s(p) = p_sat · (1 - exp(-p / p_sat)) of the
    # pressure p over it, linear for light touches, levelling off as the soft dielectric
    # densifies; 0 = linear. Fitted to the grey levels of real prints (no published response
    # of the paper's skin): module docstring.
    saturation_pa: float = SATURATION_PA

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


def saturate(pressure_pa: np.ndarray, saturation_pa: float) -> np.ndarray:
    """What a pad reads of the pressure over it: p_sat · (1 - exp(-p / p_sat)), Pa ((..., N)
    float, Pa, in and out); the identity for ``saturation_pa`` = 0. Slope 1 at p = 0, never above
    p or p_sat."""
    p = np.asarray(pressure_pa, dtype=np.float64)
    if saturation_pa <= 0:
        return p
    return -saturation_pa * np.expm1(-p / saturation_pa)


def force_consistent_pressure(
    base_pa: np.ndarray, area_m2: np.ndarray, force_n: float
) -> np.ndarray:
    """Scale a pressure field so that its resultant equals a measured normal force.

    base_pa : (N,) float, Pa, >= 0 (the foundation field; its shape is kept). area_m2 : (N,)
    float, m², taxel areas. force_n : normal force on the pressed taxels, N. Returns (N,) float,
    Pa with sum(p · area) = force_n; all zeros when nothing is pressed or the force is <= 0.
    """
    base = np.asarray(base_pa, dtype=np.float64)
    resultant = float(base @ area_m2)
    if resultant <= 0.0 or force_n <= 0.0:
        return np.zeros_like(base)
    return base * (force_n / resultant)


def lattice_spacing_m(positions_m: np.ndarray) -> float:
    """Median distance (m) from each taxel (N, 3) m to its nearest neighbour."""
    dist, _ = cKDTree(positions_m).query(positions_m, k=2)
    return float(np.median(dist[:, 1]))


def taxel_areas_m2(positions_m: np.ndarray, faces: np.ndarray | None = None) -> np.ndarray:
    """Area (N,) m² each taxel stands for on the sensor mesh.

    positions_m : (N, 3) float, m. faces : (M, 3) int taxel triangles, or None. With faces, one
    third of the areas of the triangles incident on each taxel (they sum to the mesh's area);
    without, the hexagonal cell of the lattice, spacing² · √3 / 2 (`lattice_spacing_m`).
    """
    n = positions_m.shape[0]
    if faces is None or len(faces) == 0:
        return np.full(n, lattice_spacing_m(positions_m) ** 2 * np.sqrt(3.0) / 2.0)
    tri = positions_m[np.asarray(faces)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    return np.bincount(np.asarray(faces).ravel(), np.repeat(area / 3.0, 3), minlength=n)


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
    dead : (N,) bool — taxels that read only their baseline (faults from `tactile.images.faults`).
    area_m2 : (N,) float, m² — taxel areas (`taxel_areas_m2`); spacing_m : float, m — the pitch
    of a hexagonal lattice with the median taxel area (the pad pitch, e.g. 10.6 mm on the
    forearm; nearest-neighbour distances are shorter where an iCub module's pads crowd).
    """

    cfg: SkinConfig
    spread: csr_matrix
    gain: np.ndarray
    baseline_counts: np.ndarray
    drift_counts_per_s: np.ndarray
    dead: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    area_m2: np.ndarray = field(default_factory=lambda: np.zeros(0))
    spacing_m: float = 0.0

    @classmethod
    def create(
        cls,
        positions_m: np.ndarray,
        cfg: SkinConfig,
        rng: np.random.Generator,
        faces: np.ndarray | None = None,
    ) -> SkinInstance:
        """Draw the per-taxel gain, baseline and drift rate for taxels at positions_m (N, 3), m;
        ``faces`` (M, 3) int: the sensor mesh, for the taxel areas (None: lattice cells)."""
        n = positions_m.shape[0]
        gain = np.maximum(rng.normal(1.0, cfg.gain_spread, n), 0.05)
        base = rng.normal(cfg.baseline_counts, cfg.baseline_spread_counts, n)
        drift = rng.normal(0.0, cfg.drift_std_counts_per_s, n)
        spread = spread_matrix(positions_m, cfg.spread_sigma_m, cfg.spread_cutoff_sigmas)
        area = taxel_areas_m2(positions_m, faces)
        spacing = float(np.sqrt(2.0 * np.median(area) / np.sqrt(3.0)))  # hex pitch of that cell
        return cls(cfg, spread, gain, base, drift, np.zeros(n, dtype=bool), area, spacing)

    def with_dead_modules(
        self, module_ids: np.ndarray, n: int, rng: np.random.Generator
    ) -> SkinInstance:
        """A copy where n random whole modules (module_ids (N,)) are dead."""
        return replace(self, dead=self.dead | dead_modules(module_ids, n, rng))

    @property
    def n_taxels(self) -> int:
        return int(self.gain.shape[0])

    def pressure(self, depth_m: np.ndarray, force_n: float | None = None) -> np.ndarray:
        """Noise-free sensed pressure (N,) Pa from depth (N,) m: foundation law, scaled to the
        sensed normal force ``force_n`` (N; when given and ``cfg.force_consistent``), spread."""
        base = depth_to_pressure(depth_m, self.cfg)
        if force_n is not None and self.cfg.force_consistent:
            base = force_consistent_pressure(base, self.area_m2, force_n)
        return self.spread @ base

    def readout(self) -> Readout:
        """How the robot reads this skin: known baseline and drift removed, signals at or below
        `NOISE_FLOOR_SIGMAS` noise sd read 0, over the nominal gain (gains unknown to it)."""
        return Readout(
            self.cfg.counts_per_pa,
            self.baseline_counts,
            self.drift_counts_per_s,
            NOISE_FLOOR_SIGMAS * self.cfg.noise_std_counts,
        )

    def offset(self, time_s: float) -> np.ndarray:
        """Untouched reading (N,) counts at time_s: baseline plus linear drift."""
        return self.baseline_counts + self.drift_counts_per_s * time_s

    def frame(
        self,
        depth_m: np.ndarray,
        rng: np.random.Generator | None,
        time_s: float = 0.0,
        force_n: float | None = None,
    ) -> SkinFrame:
        """Depth (N,) m -> `SkinFrame`. rng=None gives the noise-free reading; ``force_n``: the
        sensed normal force (N) the pressure is scaled to (`pressure`)."""
        if np.shape(depth_m) != (self.n_taxels,):
            raise ConfigError(f"depth has shape {np.shape(depth_m)}; expected ({self.n_taxels},)")
        pressure = self.pressure(depth_m, force_n)
        offset = self.offset(time_s)
        gain = np.where(self.dead, 0.0, self.gain) if self.dead.size else self.gain
        counts = offset + gain * self.cfg.counts_per_pa * saturate(pressure, self.cfg.saturation_pa)
        if rng is not None and self.cfg.noise_std_counts > 0:
            counts = counts + rng.normal(0.0, self.cfg.noise_std_counts, self.n_taxels)
        reading = quantize(counts)
        return SkinFrame(np.asarray(depth_m), pressure, reading, reading - offset)
