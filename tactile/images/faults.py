"""Sensor faults for robustness tests (pure functions, seeded by ``np.random.Generator``).

Test A (Albini & Cannata 2020): blind spots — every taxel within a radius, measured on the flat
map, of a few random taxels reads zero. Test B: random removal of a growing fraction of taxels,
nested so that each larger removal contains the smaller ones (rebuild the map with
``layout.subset(kept)``). Also: dead modules, stuck-at taxels and gain drift on pressure arrays.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from tactile.errors import ConfigError

if TYPE_CHECKING:
    from tactile.images.tactile_map import TactileMap


def _uv_of(map_or_uv: TactileMap | np.ndarray) -> np.ndarray:
    uv = np.asarray(getattr(map_or_uv, "uv", map_or_uv), dtype=np.float64)
    if uv.ndim != 2 or uv.shape[1] != 2:
        raise ConfigError(f"expected a TactileMap or taxel uv (N, 2) in mm, got shape {uv.shape}")
    return uv


def blind_spots(
    map_or_uv: TactileMap | np.ndarray, n_spots: int, radius_mm: float, rng: np.random.Generator
) -> np.ndarray:
    """Test A: taxels silenced by ``n_spots`` blind spots on the flat map.

    Centres are distinct random placed taxels; every taxel whose uv lies within ``radius_mm`` of a
    centre (Euclidean, on the map) is blind. Unplaced (NaN uv) taxels are never blind.

    Parameters
    ----------
    map_or_uv : TactileMap, or (N, 2) float taxel uv in mm.
    n_spots : int >= 0. radius_mm : float >= 0, mm. rng : np.random.Generator.

    Returns
    -------
    blind : (N,) bool — True for taxels that read zero (apply with :func:`zero_taxels`).
    """
    uv = _uv_of(map_or_uv)
    placed = np.flatnonzero(np.isfinite(uv).all(axis=1))
    if not 0 <= n_spots <= len(placed):
        raise ConfigError(f"n_spots must be in 0..{len(placed)} (placed taxels), got {n_spots}")
    if not radius_mm >= 0:
        raise ConfigError(f"radius_mm must be >= 0 mm, got {radius_mm}")
    centres = uv[rng.choice(placed, size=n_spots, replace=False)]
    dist2 = ((uv[placed, None, :] - centres[None, :, :]) ** 2).sum(axis=-1)
    blind = np.zeros(len(uv), dtype=bool)
    blind[placed] = (dist2 <= radius_mm**2).any(axis=1)
    return blind


def nested_removal(
    n_taxels: int, fractions: Sequence[float], rng: np.random.Generator
) -> list[np.ndarray]:
    """Test B: taxels kept after removing each fraction at random, removals nested.

    One random order of the taxels is drawn; removing a fraction f drops the first
    ``round(f * n_taxels)`` of it, so the taxels kept at a larger fraction are a subset of those
    kept at a smaller one.

    Parameters
    ----------
    n_taxels : int. fractions : floats in [0, 1]. rng : np.random.Generator.

    Returns
    -------
    kept : one (K_i,) int64 array of sorted taxel indices per fraction, in the given order.
    """
    fr = np.asarray(fractions, dtype=np.float64)
    if fr.ndim != 1 or not ((fr >= 0) & (fr <= 1)).all():
        raise ConfigError(f"fractions must be a list of numbers in [0, 1], got {fractions!r}")
    order = rng.permutation(n_taxels)
    n_removed = np.rint(fr * n_taxels).astype(np.int64)
    return [np.sort(order[k:]).astype(np.int64) for k in n_removed]


def dead_modules(module_ids: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Taxels of ``n`` random whole modules (e.g. one skin triangle's 10 taxels) that died.

    Parameters
    ----------
    module_ids : (N,) int, module of each taxel; -1 (unknown) never dies. n : int >= 0.

    Returns
    -------
    dead : (N,) bool.
    """
    ids = np.asarray(module_ids)
    modules = np.unique(ids[ids >= 0])
    if not 0 <= n <= len(modules):
        raise ConfigError(f"n must be in 0..{len(modules)} (known modules), got {n}")
    return np.isin(ids, rng.choice(modules, size=n, replace=False))


def zero_taxels(p: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """Pressures with the masked taxels reading zero. p : (N,) or (B, N). mask : (N,) bool."""
    return np.where(np.asarray(mask, dtype=bool), 0.0, p)


def stuck_at(
    p: np.ndarray, fraction: float, rng: np.random.Generator, *, value: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """A random fraction of taxels stuck at a constant reading over all frames.

    Parameters
    ----------
    p : (N,) or (B, N) float pressures. fraction : float in [0, 1]. rng : np.random.Generator.
    value : the stuck reading (same unit as p); by default each stuck taxel holds a random
        value uniform in [0, max p].

    Returns
    -------
    faulty : same shape as p. stuck : (N,) bool.
    """
    if not 0 <= fraction <= 1:
        raise ConfigError(f"fraction must be in [0, 1], got {fraction}")
    p = np.asarray(p, dtype=np.float64)
    n = p.shape[-1]
    stuck = np.zeros(n, dtype=bool)
    stuck[rng.choice(n, size=round(fraction * n), replace=False)] = True
    high = float(p.max(initial=0.0))
    level = rng.uniform(0.0, high, n) if value is None else np.full(n, float(value))
    return np.where(stuck, level, p), stuck


def gain_drift(
    p: np.ndarray, sigma: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Per-taxel multiplicative gain drift, log-normal: gain = exp(N(0, sigma²)), fixed over frames.

    Parameters
    ----------
    p : (N,) or (B, N) float pressures. sigma : float >= 0, std of log gain. rng : Generator.

    Returns
    -------
    drifted : same shape as p. gains : (N,) float.
    """
    if not sigma >= 0:
        raise ConfigError(f"sigma must be >= 0, got {sigma}")
    p = np.asarray(p, dtype=np.float64)
    gains = np.exp(rng.normal(0.0, sigma, p.shape[-1]))
    return p * gains, gains
