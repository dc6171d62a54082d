"""Simulation settings of the fidelity experiment, from cheap to rich, as changes of a
`sim.gen_config.GenerateConfig`.

Each setting is a set of dotted-key changes (``{"episode.timestep_s": 0.001}``) laid over one
base configuration, so a knob added to `GenerateConfig` later becomes a setting by one line here.
The knobs that exist (docs/fidelity.md says why the others are not swept):

- ``episode.timestep_s`` — MuJoCo time step, s. 5 ms is the default and the largest the hand's
  soft tissue allows (`sim.hand.set_hand_options`: half the 10 ms tissue time constant), so the
  time step can only be made *richer* (2.5 ms, 1 ms).
- ``episode.skin.spread_sigma_m`` — Gaussian spread of pressure through the skin's dielectric,
  m; 0 turns it off (each taxel reads only its own depth).
- ``duration_scale`` — length of every simulated press (approach, load, hold, release),
  unitless; 0.5 simulates half the time (the "sequence length" of the issue).
- ``keep_sequences`` — also simulate the release and store the 10 Hz sequence; the selected frame
  (hence the image) is the same as without it, so it is pure cost for a single-frame model.
- ``hand_detail`` — "coarse" drops the palm's metacarpal and heel capsules (`sim.hand`).
- ``episode.solver_iterations`` — MuJoCo's cap on solver iterations per step (default 100).

The richest setting (`RICHEST`) also gives the shared test set (its dataset's test split).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from tactile.errors import ConfigError

if TYPE_CHECKING:
    from sim.gen_config import GenerateConfig


@dataclass(frozen=True)
class FidelitySetting:
    """One simulation setting: a name, what it changes (dotted GenerateConfig keys) and why."""

    name: str
    changes: Mapping[str, object] = field(default_factory=dict)
    note: str = ""


SETTINGS: tuple[FidelitySetting, ...] = (
    FidelitySetting(
        "cheapest",
        {"duration_scale": 0.5, "episode.skin.spread_sigma_m": 0.0},
        "half-length presses, no skin spread",
    ),
    FidelitySetting("short", {"duration_scale": 0.5}, "half-length presses"),
    FidelitySetting("no_spread", {"episode.skin.spread_sigma_m": 0.0}, "no skin spread"),
    FidelitySetting(
        "coarse_hand",
        {"hand_detail": "coarse"},
        "palm of two flat boxes (no metacarpal or heel capsules)",
    ),
    FidelitySetting("solver_1", {"episode.solver_iterations": 1}, "1 solver iteration per step"),
    FidelitySetting("default", {}, "GenerateConfig defaults"),
    FidelitySetting(
        "sequences", {"keep_sequences": True}, "release simulated, 10 Hz sequence stored"
    ),
    FidelitySetting("dt_2.5ms", {"episode.timestep_s": 0.0025}, "time step 2.5 ms"),
    FidelitySetting("rich", {"episode.timestep_s": 0.001}, "time step 1 ms; gives the test set"),
)
BY_NAME: dict[str, FidelitySetting] = {s.name: s for s in SETTINGS}
DEFAULT = "default"  # the setting equal to the current GenerateConfig defaults
RICHEST = "rich"  # the setting of the shared test set
QUICK = ("cheapest", "short", "no_spread", "default", "rich")
# Columns of the settings table: (header with unit, dotted key, scale to the shown unit).
KNOB_COLUMNS: tuple[tuple[str, str, float], ...] = (
    ("time step (ms)", "episode.timestep_s", 1e3),
    ("skin spread σ (mm)", "episode.skin.spread_sigma_m", 1e3),
    ("press length (× default)", "duration_scale", 1.0),
    ("sequences kept", "keep_sequences", 1.0),
    ("solver iterations (cap)", "episode.solver_iterations", 1.0),
    ("hand detail", "hand_detail", 1.0),
)


def resolve_settings(names: str | Sequence[str] | None, quick: bool) -> list[FidelitySetting]:
    """The settings to run, in the cheap → rich order of `SETTINGS`.

    names : comma-separated text or a sequence of names; None = `QUICK` (quick) or all.
    ConfigError naming the unknown names and listing the known ones.
    """
    if names is None:
        names = QUICK if quick else [s.name for s in SETTINGS]
    if isinstance(names, str):
        names = [n.strip() for n in names.split(",") if n.strip()]
    unknown = [n for n in names if n not in BY_NAME]
    if unknown or not names:
        raise ConfigError(
            f"unknown fidelity setting(s) {', '.join(unknown) or '(none given)'}; "
            f"choose among: {', '.join(BY_NAME)}"
        )
    return [s for s in SETTINGS if s.name in set(names)]


def chunk_size_for(n: int) -> int:
    """Samples per chunk for an ``n``-sample set: about 8 chunks (so 2+ workers share the work),
    at most the generator's default 32. Depends on ``n`` only, never on the worker count."""
    return max(1, min(32, math.ceil(n / 8)))


def setting_config(
    setting: FidelitySetting, base: GenerateConfig, *, n: int, seed: int
) -> GenerateConfig:
    """``base`` (a GenerateConfig) with ``n``, ``seed``, the skin seed and the chunk size set,
    then the setting's changes; validated (ConfigError names the field)."""
    from tactile.config import override

    table = {"n": n, "seed": seed, "chunk_size": chunk_size_for(n), "episode.skin_seed": seed}
    return override(override(base, table), dict(setting.changes))


def knob_values(cfg: GenerateConfig) -> list[object]:
    """The `KNOB_COLUMNS` values of a GenerateConfig, in the shown units."""
    out: list[object] = []
    for _, key, scale in KNOB_COLUMNS:
        value: object = cfg
        for part in key.split("."):
            value = getattr(value, part)
        out.append(value if isinstance(value, bool | str) else float(value) * scale)
    return out


def config_tag(cfg: GenerateConfig) -> str:
    """A short stable hash of a GenerateConfig (folder names: another config, another folder)."""
    import hashlib

    from tactile.config import to_dict

    text = json.dumps(to_dict(cfg), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:10]
