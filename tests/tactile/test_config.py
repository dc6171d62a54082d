"""Config files: nested dataclasses from TOML, with clear errors and a lossless round trip."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import pytest

from tactile.config import from_dict, load_config, override, to_dict, to_toml
from tactile.errors import ConfigError


@dataclass(frozen=True)
class Inner:
    noise_counts: float = 100.0  # counts
    shape: tuple[int, int] = (68, 100)  # pixels

    def __post_init__(self) -> None:
        if not 0 <= self.noise_counts <= 1000:
            raise ConfigError(f"noise_counts must be in [0, 1000] counts, got {self.noise_counts}")


@dataclass(frozen=True)
class Outer:
    n: int = 10
    name: str = "forearm"
    hand_fraction: float | None = None
    inner: Inner = field(default_factory=Inner)
    lr_factors: dict[str, float] = field(default_factory=dict)  # e.g. {"first_two_convs": 0.1}


def test_toml_file_fills_nested_fields_and_keeps_defaults(tmp_path: Path):
    path = tmp_path / "c.toml"
    path.write_text("n = 5\n[inner]\nnoise_counts = 20\nshape = [34, 50]\n")
    cfg = load_config(path, Outer)
    assert cfg == Outer(n=5, inner=Inner(noise_counts=20.0, shape=(34, 50)))


def test_mapping_fields_read_tables_with_typed_values(tmp_path: Path):
    path = tmp_path / "m.toml"
    path.write_text("[lr_factors]\nfirst_two_convs = 0.1\nlast_layer = 1\n")
    assert load_config(path, Outer).lr_factors == {"first_two_convs": 0.1, "last_layer": 1.0}
    with pytest.raises(ConfigError, match=r"lr_factors\.x: expected float"):
        from_dict(Outer, {"lr_factors": {"x": "fast"}})


def test_round_trip_through_toml_text(tmp_path: Path):
    cfg = Outer(n=3, name="end_effector", hand_fraction=0.5, inner=Inner(7.5, (1, 2)))
    path = tmp_path / "r.toml"
    path.write_text(to_toml(cfg))
    assert load_config(path, Outer) == cfg


@pytest.mark.parametrize(
    ("table", "message"),
    [
        ({"m": 1}, "unknown key 'm'.*known keys: hand_fraction, inner, lr_factors, n, name"),
        ({"inner": {"noise": 1}}, r"unknown key 'inner.noise'.*noise_counts, shape"),
        ({"n": 1.5}, "n: expected int"),
        ({"n": True}, "n: expected int"),
        ({"inner": {"noise_counts": 5000}}, r"noise_counts must be in \[0, 1000\]"),
        ({"inner": {"shape": [1, 2, 3]}}, "expected 2 values"),
    ],
)
def test_bad_tables_name_the_field(table: dict, message: str):
    with pytest.raises(ConfigError, match=message):
        from_dict(Outer, table)


def test_bad_toml_syntax_names_the_file(tmp_path: Path):
    path = tmp_path / "bad.toml"
    path.write_text("n = = 3\n")
    with pytest.raises(ConfigError, match=r"bad\.toml: not valid TOML"):
        load_config(path, Outer)


def test_override_dotted_keys_and_rejects_unknown():
    cfg = override(Outer(), {"inner.noise_counts": 1.0, "n": 2})
    assert cfg.inner.noise_counts == 1.0 and cfg.n == 2
    assert to_dict(cfg)["inner"]["shape"] == [68, 100]
    with pytest.raises(ConfigError, match=r"unknown key 'inner\.nope'"):
        override(cfg, {"inner.nope": 1})
