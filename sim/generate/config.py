"""`GenerateConfig`: everything that shapes a synthetic dataset, validated before any simulation.

One frozen dataclass (the generation stage) nesting the episode runner's `EpisodeConfig`, which
nests the skin model's `SkinConfig`. Loaded from TOML with `load_generate_config` (unknown keys
and wrong types refused by `tactile.config`), every field range-checked in ``__post_init__`` with
a `ConfigError` naming the dotted field and its allowed range. The resolved config is the
dataset's fingerprint (`tactile.dataset.manifest`): the worker count, the shard and the executor
are *not* in it, since they never change the bytes.

    cfg = load_generate_config("docs/generate_example.toml", n=200, seed=3)
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

from handskin import __version__
from sim.contactors.hand import HAND_DETAILS
from sim.episode.runner import EpisodeConfig
from sim.skin import DEFAULT_PART
from sim.skin.parts import PARTS
from tactile.config import RECORD_WHEN_SET, from_dict, load_config, override
from tactile.dataset.manifest import MANIFEST, read_manifest
from tactile.dataset.splits import METHODS
from tactile.errors import ConfigError, DataError

PAPER_SAMPLES = 3530  # Albini & Cannata, IJRR 2020: 1,710 hand + 1,820 non-hand contacts
PAPER_HAND_FRACTION = 1710 / 3530
MESH_SUFFIXES = (".stl", ".obj")
MAX_CHUNKS = 10**6  # chunk file names have six digits
# Simulators: "mujoco" (C MuJoCo, one episode at a time per worker) or "warp" (MuJoCo Warp, many
# episodes as the worlds of one batched model; `sim.warp.backend`, the warp extra).
BACKENDS = ("mujoco", "warp")
# (low, high) inclusive ranges; None = unbounded on that side.
RANGES: dict[str, tuple[float | None, float | None]] = {
    "n": (1, 10**8),
    "hand_fraction": (0.0, 1.0),
    "seed": (0, 2**63 - 1),
    "chunk_size": (1, 4096),
    "n_subjects": (1, 9999),
    "instances_per_kind": (1, 1000),
    "duration_scale": (0.1, 2.0),
    "sequence_frames": (1, 600),
    "episode.timestep_s": (1e-4, 0.01),
    "episode.map_step_mm": (0.1, 5.0),
    "episode.solver_iterations": (1, 1000),
    "episode.skin_seed": (0, 2**63 - 1),
    "episode.active_pa": (0.0, 1e6),
    "episode.max_attempts": (1, 100),
    "episode.min_active_taxels": (1, 100_000),
    "episode.cache_size": (1, 1024),
    "mix.fraction": (0.0, 1.0),
    "mix.same_person": (0.0, 1e6),
    "mix.two_people": (0.0, 1e6),
    "mix.hand_object": (0.0, 1e6),
    "mix.hand_body": (0.0, 1e6),
    "mix.min_gap_mm": (0.0, 1e4),
}


@dataclass(frozen=True)
class MixConfig:
    """Samples pressed by two contactors at once (`sim.generate.mix`); off by default."""

    # Share of samples with two contacts, unitless: 0 (the default) makes every sample a single
    # contact and keeps the bytes of datasets made without this option.
    fraction: float = 0.0
    # Relative weights of a hand's second contact: the same person's other hand, another
    # person's hand, an object, a body part. (An object's second is a body part; a body part's an
    # object.)
    same_person: float = 1.0
    two_people: float = 1.0
    hand_object: float = 1.0
    hand_body: float = 1.0
    # mm on the flat map: the second contact's site at least this far from the first's (a hand
    # print is ~80 mm wide, so two palms 100 mm apart barely touch).
    min_gap_mm: float = 100.0


@dataclass(frozen=True)
class GenerateConfig:
    """A synthetic dataset: what is pressed, how many, on which part, with which skin.

    Defaults reproduce the paper's dataset size and class balance on the forearm.
    """

    # Built-in part (`sim.skin.parts.PARTS`; `sim.skin.DEFAULT_PART`, the forearm at 7.6 mm pad
    # pitch) or a link mesh file (.stl/.obj, metres), covered like Baxter W0
    # (`sim.skin.parts.W0_REGION`); the mesh's sha256 enters the fingerprint.
    part: str = DEFAULT_PART
    n: int = PAPER_SAMPLES  # samples in the dataset (3,530 as in the paper)
    # Fraction of hand samples, unitless; 1710/3530 as in the paper. Sample i's class is fixed by
    # `sim.generate.sampler.is_hand_index` (exact over every prefix, independent of n).
    hand_fraction: float = PAPER_HAND_FRACTION
    seed: int = 0  # dataset seed: sample i draws from SeedSequence(seed, spawn_key=(i, attempt))
    # Samples per chunk (the unit of atomic writing, resuming and parallel work); 32 keeps a
    # chunk to a few seconds of work, so a kill loses little and the progress bar moves.
    chunk_size: int = 32
    keep_sequences: bool = False  # also store the 10 Hz raw sequence of every episode
    # T, frames of the stored sequence (10 Hz, zero-padded): 3 s holds every interaction model's
    # approach + load + hold + release (hands ~1.3 s, objects and body parts <= 2 s).
    sequence_frames: int = 30
    # Simulated people (ids s0000..): 90 volunteers as in the paper. Drawn from the dataset seed
    # (reserved spawn key), so the same seed gives the same people whatever n is.
    n_subjects: int = 90
    # Train/test split (`tactile.dataset.splits.METHODS`): "greedy" (sample fractions closest to
    # 70/30) or "keyed" (a subject's or instance's side fixed by the seed and its id alone, so
    # datasets of one seed on any part and of any n hold out the same people).
    split: str = "greedy"
    instances_per_kind: int = 20  # object / body-part instances per type (`sim.contactors.nonhand`)
    # Collision detail of the hands (`sim.contactors.hand.HAND_DETAILS`): "full" (metacarpal and
    # heel capsules round the palm) or "coarse" (the palm is two flat boxes); fingers are the same.
    hand_detail: str = "full"
    # Multiplier on every press plan's phase durations (approach, load, hold, release),
    # unitless; 1 = the interaction models' own timing, < 1 for quick smoke tests
    # (`sim.generate.tiny`).
    duration_scale: float = 1.0
    # Simulator (`BACKENDS`): the two give statistically equivalent data, not the same bytes, so
    # the backend is part of the dataset's identity (a folder of one is never resumed by other).
    backend: str = field(default="mujoco", metadata=RECORD_WHEN_SET)
    # Episode runner (time step s, active threshold Pa, retries, scene cache) and its nested skin
    # model ([episode.skin]: stiffness Pa/m, noise counts, ...). episode.part follows `part`.
    episode: EpisodeConfig = field(default_factory=EpisodeConfig)
    # Several contacts at once ([mix]: fraction, weights, min_gap_mm); recorded only when set.
    mix: MixConfig = field(default_factory=MixConfig, metadata=RECORD_WHEN_SET)

    def __post_init__(self) -> None:
        for name, (lo, hi) in RANGES.items():
            check_range(name, _get(self, name), lo, hi)
        check_part(self.part)
        if self.split not in METHODS:
            raise ConfigError(f"split = {self.split!r} unknown; choose one of {', '.join(METHODS)}")
        if self.mix.fraction > 0 and self.split != "keyed":
            raise ConfigError(
                f'mix.fraction = {self.mix.fraction:g} needs split = "keyed" (a sample\'s two '
                'contactors must fall on one side of the split); set split = "keyed"'
            )
        weights = (self.mix.same_person, self.mix.two_people, self.mix.hand_object)
        if self.mix.fraction > 0 and not sum(weights) + self.mix.hand_body > 0:
            raise ConfigError(
                "mix: give at least one of same_person, two_people, hand_object, "
                "hand_body a weight > 0"
            )
        if self.backend not in BACKENDS:
            raise ConfigError(
                f"backend = {self.backend!r} unknown; choose one of {', '.join(BACKENDS)}"
            )
        if self.hand_detail not in HAND_DETAILS:
            raise ConfigError(
                f"hand_detail = {self.hand_detail!r} unknown; choose one of "
                f"{', '.join(HAND_DETAILS)}"
            )
        if self.episode.part not in (self.part, EpisodeConfig.part):
            raise ConfigError(
                f"episode.part = {self.episode.part!r} differs from part = {self.part!r}; "
                "set the part with the top-level `part` key (or --part) only"
            )
        object.__setattr__(self, "episode", replace(self.episode, part=self.part))
        if math.ceil(self.n / self.chunk_size) > MAX_CHUNKS:
            raise ConfigError(
                f"n / chunk_size = {self.n}/{self.chunk_size} > {MAX_CHUNKS} chunks; "
                "raise chunk_size"
            )

    @property
    def n_chunks(self) -> int:
        """Number of chunks of ``n`` samples."""
        return math.ceil(self.n / self.chunk_size)

    def part_id(self) -> str:
        """The part as recorded in the manifest: its name, or ``mesh:<file>@<sha256 prefix>``."""
        if not is_mesh_path(self.part):
            return self.part
        digest = hashlib.sha256(Path(self.part).read_bytes()).hexdigest()[:16]
        return f"mesh:{Path(self.part).name}@{digest}"


def _get(cfg: Any, dotted: str) -> Any:
    for key in dotted.split("."):
        cfg = getattr(cfg, key)
    return cfg


def check_range(name: str, value: Any, lo: float | None, hi: float | None) -> None:
    """ConfigError naming ``name`` unless ``lo <= value <= hi`` (and finite)."""
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    ok = ok and (lo is None or value >= lo) and (hi is None or value <= hi)
    if not ok:
        raise ConfigError(
            f"{name} = {value!r} is out of range; allowed [{_num(lo, '-inf')}, {_num(hi, 'inf')}]"
        )


def _num(x: float | None, unbounded: str) -> str:
    if x is None:
        return unbounded
    return str(int(x)) if float(x).is_integer() else f"{x:g}"


def is_mesh_path(part: str) -> bool:
    """Whether ``part`` names a link mesh file rather than a built-in part."""
    return Path(part).suffix.lower() in MESH_SUFFIXES


def check_part(part: str) -> None:
    """ConfigError unless ``part`` is a built-in part or an existing .stl/.obj file."""
    if part in PARTS:
        return
    if is_mesh_path(part):
        if not Path(part).is_file():
            raise ConfigError(f"part = {part!r}: mesh file not found")
        return
    raise ConfigError(
        f"unknown part {part!r}; known parts: {', '.join(PARTS)}, or a link mesh file "
        f"({'/'.join(MESH_SUFFIXES)}, metres)"
    )


def load_generate_config(path: str | Path | None = None, **changes: Any) -> GenerateConfig:
    """The configuration of ``path`` (TOML; defaults when None) with top-level ``changes``
    (``n=200``; None values ignored), validated. ConfigError names the field and range."""
    cfg = load_config(path, GenerateConfig) if path is not None else None
    table = {k: v for k, v in changes.items() if v is not None}
    if cfg is None:
        return from_dict(GenerateConfig, table)
    if "part" in table:
        table["episode.part"] = table["part"]  # the resolved episode.part follows part
    return override(cfg, table) if table else cfg


def generator_version() -> str:
    """``<handskin version>+src.<sha256 prefix of sim/ and tactile/ sources>``: in the
    fingerprint, so a folder started by other code is refused instead of mixed."""
    root = Path(__file__).resolve().parents[2]  # above sim/ (this file: sim/generate/config.py)
    digest = hashlib.sha256()
    for path in sorted([*root.glob("sim/**/*.py"), *root.glob("tactile/**/*.py")]):
        digest.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes())
    return f"{__version__}+src.{digest.hexdigest()[:12]}"


def refuse_other_code(out: Path, manifest: dict) -> None:
    """DataError when ``out`` was started with the same configuration but other generator code."""
    if not (out / MANIFEST).is_file():
        return
    old = read_manifest(out)
    same = all(old.get(k) == manifest[k] for k in ("config", "part", "seed"))
    if same and old.get("generator_version") != manifest["generator_version"]:
        raise DataError(
            f"{out} was started by other generator code ({old.get('generator_version')}; now "
            f"{manifest['generator_version']}): sim/ or tactile/ changed since, so its chunks "
            "cannot be mixed with new ones. Fix: a new --out folder, or the original code"
        )


def refuse_other_backend(out: Path, manifest: dict) -> None:
    """DataError when ``out`` was started with the other simulator backend (`BACKENDS`)."""
    if not (out / MANIFEST).is_file():
        return
    old = read_manifest(out)["config"].get("backend", "mujoco")
    new = manifest["config"].get("backend", "mujoco")  # recorded only when set
    if old != new:
        raise DataError(
            f"{out} holds a dataset generated with --backend {old}; this run asks for --backend "
            f"{new}. The backends' data agree statistically, not byte for byte, so their chunks "
            f"are never mixed. Fix: a new --out folder, or --backend {old}"
        )
