"""Raw skin readings back to the pressures a dataset's images were made from.

    ro = Readout.of(attrs)                       # from a dataset's root attributes
    p = ro.pressure_pa(raw, time_s)              # (B, N) counts, (B,) s -> (B, N) Pa

The generator images what this readout gives (`sim.skin.model.SkinInstance.readout`, used by
`sim.episode.frames.sensed_pressure`): ``reading - (baseline + drift * t)``, with signals at or
below the noise floor (4 noise sd) read as 0, over the nominal gain (the per-taxel gain spread is
unknown to a robot, so it is not undone). A dataset stores it as root attributes (`attrs`);
with all of them stored, the images regenerated from ``raw`` and ``time_s`` equal the stored
ones (tests/sim/test_generate.py).

Attributes (all optional; a missing one is the identity):
- ``skin_counts_per_pa`` : float, counts/Pa (1.0: pressures in counts);
- ``skin_baseline_counts`` : float or (N,) float, counts (0);
- ``skin_drift_counts_per_s`` : float or (N,) float, counts/s (0);
- ``skin_noise_floor_counts`` : float, counts (0). Datasets generated before this attribute
  existed give it as ``config.episode.skin.noise_std_counts`` times `LEGACY_FLOOR_SIGMAS`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from tactile.errors import DataError

#: The generator reads signals up to this many noise sd above the untouched reading as 0. Real
#: prints (../shared/data/real_hands) hold almost no faint isolated mark: 0.03 blobs per print
#: peak at or below 30 of 255, where a 3 sd floor left 1.75 per simulated hand print (1,488
#: taxels: 0.13 % of them above 3 sd of noise in every frame) and 4 sd 0.16 (default set).
NOISE_FLOOR_SIGMAS = 4.0
#: The floor of datasets written before they stored it (`skin_noise_floor_counts`): 3 noise sd.
LEGACY_FLOOR_SIGMAS = 3.0
MAX_COUNT = 65535  # 16-bit readings: a raw count is an integer in 0..MAX_COUNT


def count_fault(values: np.ndarray) -> tuple[tuple[int, ...], str] | None:
    """(index, rule broken) of the first value of ``values`` (finite floats) that is no raw
    count, an integer in 0..``MAX_COUNT``; None when all are (``handskin ingest``, ``predict``
    and ``stream`` refuse such frames)."""
    values = np.asarray(values, dtype=np.float64)
    for bad, rule in (
        ((values < 0) | (values > MAX_COUNT), f"outside 0..{MAX_COUNT} (16-bit counts)"),
        (values != np.round(values), "not an integer count"),
    ):
        if bad.any():
            return tuple(int(i) for i in np.argwhere(bad)[0]), rule
    return None


@dataclass(frozen=True)
class Readout:
    """How raw counts become pressures (Pa).

    gain_counts_per_pa : float, counts/Pa. baseline_counts, drift_counts_per_s : () or (N,)
    float, counts and counts/s. floor_counts : float, counts — signals at or below it read 0.
    """

    gain_counts_per_pa: float = 1.0
    baseline_counts: np.ndarray | float = 0.0
    drift_counts_per_s: np.ndarray | float = 0.0
    floor_counts: float = 0.0

    @classmethod
    def of(cls, attrs: Mapping[str, object]) -> Readout:
        """The readout described by a dataset's decoded root attributes (see module doc)."""
        floor = attrs.get("skin_noise_floor_counts")
        if floor is None:
            config = attrs.get("config") if isinstance(attrs.get("config"), dict) else {}
            skin = (config.get("episode") or {}).get("skin") or {}
            floor = LEGACY_FLOOR_SIGMAS * float(skin.get("noise_std_counts", 0.0))
        gain = float(attrs.get("skin_counts_per_pa", 1.0))
        if not gain > 0:
            raise DataError(
                f"skin_counts_per_pa = {gain} must be > 0 counts/Pa. Fix: re-ingest "
                "the recording with its skin's gain (--counts-per-pa)"
            )
        return cls(
            gain,
            np.asarray(attrs.get("skin_baseline_counts", 0.0), dtype=np.float64),
            np.asarray(attrs.get("skin_drift_counts_per_s", 0.0), dtype=np.float64),
            float(floor),
        )

    def pressure_pa(self, raw: np.ndarray, time_s: np.ndarray | float | None = None) -> np.ndarray:
        """Pressures, Pa, float64, shaped as ``raw``.

        raw : (N,) or (B, N) counts. time_s : the frames' times in their episodes, s — a scalar,
        or (B,) for a batch; None reads them as 0 (no drift removed).
        """
        raw = np.asarray(raw, dtype=np.float64)
        t = np.asarray(0.0 if time_s is None else time_s, dtype=np.float64)
        if raw.ndim == 2 and t.ndim == 1:
            t = t[:, None]
        signal = raw - (self.baseline_counts + self.drift_counts_per_s * t)
        return np.where(signal > self.floor_counts, signal, 0.0) / self.gain_counts_per_pa

    def attrs(self) -> dict[str, object]:
        """The root attributes that describe this readout (the inverse of `of`)."""
        return {
            "skin_counts_per_pa": self.gain_counts_per_pa,
            "skin_baseline_counts": np.asarray(self.baseline_counts, np.float64),
            "skin_drift_counts_per_s": np.asarray(self.drift_counts_per_s, np.float64),
            "skin_noise_floor_counts": self.floor_counts,
        }
