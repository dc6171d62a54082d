"""Run options of the MuJoCo Warp backend and their checks, made before any work.

`WarpOptions` holds what shapes a warp run but not its data (like the worker count): worlds per
batch, the warp device, and the per-world contact and constraint-row capacities. `check_warp`
confirms the optional packages are installed and match MuJoCo, and that the device exists;
every error names the flag the user typed. Nothing here imports warp at module level, so the C
backend never needs it.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from importlib import metadata

import mujoco

from tactile.errors import ConfigError

EXTRA = "pip install 'handskin[warp]'"
DEVICE_PATTERN = re.compile(r"^(cpu|cuda(:\d+)?)$")
MAX_WORLDS = 1 << 16


@dataclass(frozen=True)
class WarpOptions:
    """How a warp run batches its episodes (none of it changes the data on the CPU device)."""

    # Episodes stepped together as the worlds of one model (count). Larger batches amortise the
    # per-step kernel launches: on the CPU device 8 worlds cost 2.6 ms per world-step, 128 worlds
    # 0.3 ms (forearm, a hand family); a GPU wants thousands.
    worlds: int = 64
    device: str = "cpu"  # warp device: cpu, cuda or cuda:N
    # Contacts per world (count; MJWarp pools nconmax x worlds for the batch). None: derived per
    # structure family from its contactor geoms, with a safety factor (`sim.warp.jobs`).
    nconmax: int | None = None
    njmax: int | None = None  # constraint rows per world (count); None: derived likewise

    def __post_init__(self) -> None:
        if not 1 <= self.worlds <= MAX_WORLDS:
            raise ConfigError(f"--worlds {self.worlds} is out of range; allowed [1, {MAX_WORLDS}]")
        if not DEVICE_PATTERN.match(self.device):
            raise ConfigError(f"--device {self.device!r} unknown; give cpu, cuda or cuda:N")
        for flag, value in (("--nconmax", self.nconmax), ("--njmax", self.njmax)):
            if value is not None and not 1 <= value <= 10**7:
                raise ConfigError(f"{flag} {value} is out of range; allowed [1, 10000000]")


def check_warp(opts: WarpOptions) -> None:
    """ConfigError unless mujoco-warp is installed at MuJoCo's version and ``opts.device``
    exists; quiets warp's start-up banner and per-module load lines (warnings still show)."""
    try:  # optional: mujoco-warp (the warp extra)
        import mujoco_warp  # noqa: F401
        import warp as wp
    except ImportError as err:
        raise ConfigError(
            f"--backend warp needs the mujoco-warp package ({err}). Fix: {EXTRA}"
        ) from err
    installed = metadata.version("mujoco-warp")
    if installed != mujoco.__version__:
        raise ConfigError(
            f"--backend warp: mujoco-warp {installed} does not match mujoco {mujoco.__version__} "
            f"(their model layouts must agree). Fix: pip install 'handskin[warp]' (it pins a "
            f"pair), or pip install 'mujoco=={installed}' 'mujoco-warp=={installed}'"
        )
    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING
    wp.init()
    known = [str(d) for d in wp.get_devices()]
    if opts.device not in known and not (opts.device == "cuda" and wp.is_cuda_available()):
        raise ConfigError(f"--device {opts.device} is not available; warp sees {', '.join(known)}")


def simulator_label(opts: WarpOptions) -> str:
    """What a warp dataset records of its simulator: packages and device."""
    return (
        f"mujoco-warp {metadata.version('mujoco-warp')}, warp-lang "
        f"{metadata.version('warp-lang')}, device {opts.device}"
    )
