"""Simulation settings of the fidelity experiment, from cheap to rich, as changes of a
`sim.generate.config.GenerateConfig`.

Each setting is a set of dotted-key changes (``{"episode.timestep_s": 0.001}``) laid over one
base configuration, so a knob of `GenerateConfig` becomes a setting by one line here. The knobs
(docs/fidelity.md says why the others are not swept):

- ``episode.timestep_s`` — MuJoCo time step, s. 5 ms is the default and the largest the hand's
  soft tissue allows (`sim.contactors.hand.set_hand_options`: half the 10 ms tissue time constant),
  so the time step can only be made *richer* (2.5 ms, 1 ms).
- ``episode.skin.spread_sigma_m`` — Gaussian spread of pressure through the skin's dielectric,
  m; 0 turns it off (each taxel reads only its own depth).
- ``duration_scale`` — length of every simulated press (approach, load, hold, release),
  unitless; 0.5 simulates half the time.
- ``keep_sequences`` — also simulate the release and store the 10 Hz sequence; the selected frame
  (hence the image) is the same as without it, so it is pure cost for a single-frame model.
- ``hand_detail`` — "coarse" drops the palm's metacarpal and heel capsules (`sim.contactors.hand`).
- ``episode.solver_iterations`` — MuJoCo's cap on solver iterations per step (default 100).
- ``backend`` — "warp" steps the episodes as batched MuJoCo Warp worlds (float32, its own
  collision and solver) on warp's default device instead of C MuJoCo.

The richest setting (`RICHEST`) also gives the shared test set (its dataset's test split).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

from tactile.config import override, to_dict
from tactile.errors import ConfigError

if TYPE_CHECKING:
    from sim.generate.config import GenerateConfig


@dataclass(frozen=True)
class FidelitySetting:
    """One simulation setting: a name, what it changes (dotted GenerateConfig keys) and why."""

    name: str
    changes: Mapping[str, object] = field(default_factory=dict)
    note: str = ""


S = FidelitySetting
SETTINGS: tuple[FidelitySetting, ...] = (
    S(
        "cheapest",
        {"duration_scale": 0.5, "episode.skin.spread_sigma_m": 0.0},
        "short presses, no spread",
    ),
    S("short", {"duration_scale": 0.5}, "half-length presses"),
    S("no_spread", {"episode.skin.spread_sigma_m": 0.0}, "no skin spread"),
    S("coarse_hand", {"hand_detail": "coarse"}, "palm without metacarpal or heel capsules"),
    S("solver_1", {"episode.solver_iterations": 1}, "1 solver iteration per step"),
    S("default", {}, "GenerateConfig defaults"),
    S("sequences", {"keep_sequences": True}, "release simulated, 10 Hz sequence stored"),
    S("dt_2.5ms", {"episode.timestep_s": 0.0025}, "time step 2.5 ms"),
    S("warp", {"backend": "warp"}, "MuJoCo Warp backend (batched worlds, float32)"),
    S("rich", {"episode.timestep_s": 0.001}, "time step 1 ms; gives the test set"),
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
    ("backend", "backend", 1.0),
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
            f"--settings: unknown setting(s) {', '.join(unknown) or '(none given)'}; "
            f"choose among: {', '.join(BY_NAME)}"
        )
    return [s for s in SETTINGS if s.name in set(names)]


def setting_config(setting: FidelitySetting, base: GenerateConfig, *, n: int, seed: int):
    """``base`` (a GenerateConfig) with ``n``, ``seed``, the skin seed and the chunk size set
    (about 8 chunks, so that workers share the work; at most the generator's 32), then the
    setting's changes; validated (ConfigError names the field)."""
    chunk = max(1, min(32, math.ceil(n / 8)))  # depends on n only, never on the workers
    table = {"n": n, "seed": seed, "chunk_size": chunk, "episode.skin_seed": seed}
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


def config_tag(obj) -> str:
    """A short stable hash of a GenerateConfig or of JSON-able parts (folder names: another
    configuration, another folder)."""
    obj = to_dict(obj) if dataclasses.is_dataclass(obj) else obj
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:10]
