"""The project's one small exception hierarchy (used by tactile/, sim/ and learn/).

Errors are raised at boundaries (files, configs, user arrays) before any work starts, and each
message names the problem and the fix.
"""

from __future__ import annotations

import math
from pathlib import Path


class HandskinError(Exception):
    """Base class of every error handskin raises on purpose."""


class LayoutError(HandskinError, ValueError):
    """A taxel layout (file or arrays) is malformed: the message names file, row and fix."""


class MapError(HandskinError, ValueError):
    """A tactile map cannot be built, loaded or applied (e.g. wrong pressure shape, NaN)."""


class ConfigError(HandskinError, ValueError):
    """A configuration value is unknown or out of range: the message names field and range."""


class DataError(HandskinError, ValueError):
    """A dataset or recording on disk is malformed, incompatible or from another configuration."""


def require_folder(
    path: Path, what: str = "--out", fix: str = "give a folder path (created if missing)"
) -> None:
    """Refuse an output folder that is, or lies under, an existing file (ConfigError naming the
    file and ``fix``), before any work starts."""
    for p in (path, *path.parents):
        if p.exists():
            if not p.is_dir():
                raise ConfigError(f"{what} {path}: {p} is a file, not a folder. Fix: {fix}")
            return


def require_positive(flag: str, value: float, unit: str = "") -> float:
    """``value`` when it is a finite number > 0, else a ConfigError naming the command-line
    ``flag`` (e.g. ``--step-mm 0 is out of range; allowed > 0 mm/pixel``)."""
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise ConfigError(
            f"{flag} {value} is out of range; allowed > 0{f' {unit}' if unit else ''}"
        )
    return value
