"""Typed configuration files: nested frozen dataclasses read from TOML and written back.

Every stage has one frozen dataclass whose fields carry units in their names and comments and
whose ``__post_init__`` checks ranges (raising ConfigError naming the field and its range). This
module turns a TOML table into such a dataclass, refusing unknown keys and wrong types before any
work starts, and writes the resolved configuration back as TOML or JSON-able dicts.

    cfg = load_config("gen.toml", GenerateConfig)   # unknown key -> ConfigError listing the known
    cfg = override(cfg, {"skin.noise_counts": 50})  # dotted overrides, validated the same way
"""

from __future__ import annotations

import dataclasses
import json
import sys
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, TypeVar

from tactile.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised on Python 3.10 only
    import tomli as tomllib

T = TypeVar("T")


def _field_types(cls: type) -> dict[str, Any]:
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls) if f.init}


def _coerce(value: Any, hint: Any, where: str) -> Any:
    """``value`` converted to the annotated type ``hint``, or ConfigError naming ``where``."""
    origin = typing.get_origin(hint)
    if dataclasses.is_dataclass(hint):
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: expected a table of {hint.__name__} fields, got {value!r}")
        return from_dict(hint, value, prefix=f"{where}.")
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(hint)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in (a for a in args if a is not type(None)):
            try:
                return _coerce(value, arg, where)
            except ConfigError as err:
                errors.append(str(err))
        raise ConfigError(errors[0])
    if origin is tuple:
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        args = typing.get_args(hint)
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_coerce(v, args[0], f"{where}[{i}]") for i, v in enumerate(value))
        if len(args) != len(value):
            raise ConfigError(f"{where}: expected {len(args)} values, got {len(value)}")
        return tuple(
            _coerce(v, a, f"{where}[{i}]") for i, (v, a) in enumerate(zip(value, args, strict=True))
        )
    if origin in (dict, Mapping, typing.Mapping) or hint is dict:
        if not isinstance(value, Mapping):
            raise ConfigError(f"{where}: expected a table, got {value!r}")
        key_t, val_t = typing.get_args(hint) or (str, Any)
        return {
            _coerce(k, key_t, where): _coerce(v, val_t, f"{where}.{k}") for k, v in value.items()
        }
    if origin is typing.Literal:
        if value not in typing.get_args(hint):
            choices = ", ".join(repr(a) for a in typing.get_args(hint))
            raise ConfigError(f"{where}: {value!r} is not one of {choices}")
        return value
    return _scalar(value, hint, where)


def _scalar(value: Any, hint: Any, where: str) -> Any:
    if hint is Any:
        return value
    if hint is float and isinstance(value, (int, float)) and not isinstance(value, bool):
        return float(value)
    if hint in (int, bool, str) and type(value) is hint:
        return value
    name = getattr(hint, "__name__", str(hint))
    raise ConfigError(f"{where}: expected {name}, got {value!r} ({type(value).__name__})")


def from_dict(cls: type[T], table: Mapping[str, Any], *, prefix: str = "") -> T:
    """Build dataclass ``cls`` from a (nested) mapping; missing keys keep their defaults.

    Raises ConfigError for unknown keys (listing the known ones), wrong types, and whatever the
    dataclass's own validation raises.
    """
    types_ = _field_types(cls)
    unknown = sorted(set(table) - set(types_))
    if unknown:
        raise ConfigError(
            f"unknown key {prefix + unknown[0]!r} in [{prefix.rstrip('.') or cls.__name__}]; "
            f"known keys: {', '.join(sorted(types_))}"
        )
    kwargs = {k: _coerce(v, types_[k], f"{prefix}{k}") for k, v in table.items()}
    try:
        return cls(**kwargs)
    except ConfigError:
        raise
    except (TypeError, ValueError) as err:
        raise ConfigError(f"[{prefix.rstrip('.') or cls.__name__}] {err}") from err


def read_toml(path: str | Path) -> dict[str, Any]:
    """The table of a TOML file; ConfigError when it is missing or not valid TOML."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError as err:
        raise ConfigError(f"config file {path} does not exist") from err
    except IsADirectoryError as err:
        raise ConfigError(f"config file {path} is a folder. Fix: give the TOML file") from err
    try:
        return tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as err:
        raise ConfigError(
            f"{path}: not a TOML file (byte 0x{data[err.start]:02x} at offset {err.start} is not "
            "UTF-8 text; a binary file?). Fix: give the configuration as a TOML text file"
        ) from None
    except tomllib.TOMLDecodeError as err:
        other = "" if path.suffix == ".toml" else f" (a {path.suffix or 'suffix-less'} file)"
        raise ConfigError(
            f"{path}: not valid TOML{other} ({err}); fix the syntax at that line"
        ) from err


def load_config(path: str | Path, cls: type[T]) -> T:
    """Read a TOML file into dataclass ``cls`` (see :func:`from_dict`)."""
    table = read_toml(path)
    try:
        return from_dict(cls, table)
    except ConfigError as err:
        raise ConfigError(f"{path}: {err}") from err


#: Field metadata of an option added after datasets were first made: a dataset's record of its
#: configuration (`record`) holds it only when it differs from its default, so a dataset made
#: without the option keeps its bytes.
RECORD_WHEN_SET = {"record": "when set"}


def record(cfg: Any) -> Any:
    """``dataclasses.asdict(cfg)`` without the `RECORD_WHEN_SET` fields left at their default."""
    if not dataclasses.is_dataclass(cfg) or isinstance(cfg, type):
        return cfg
    out = {}
    for f in dataclasses.fields(cfg):
        value = getattr(cfg, f.name)
        if f.metadata.get("record") == "when set" and value == _default(f):
            continue
        out[f.name] = record(value)
    return out


def _default(f: dataclasses.Field) -> Any:
    return f.default_factory() if f.default is dataclasses.MISSING else f.default  # type: ignore[misc]


def to_dict(cfg: Any) -> dict[str, Any]:
    """A JSON-able dict of a (nested) dataclass; tuples become lists."""
    return json.loads(json.dumps(dataclasses.asdict(cfg), default=list))


def override(cfg: T, changes: Mapping[str, Any]) -> T:
    """A copy of ``cfg`` with dotted-key changes (``{"skin.noise_counts": 50}``), re-validated."""
    table = to_dict(cfg)
    for key, value in changes.items():
        node = table
        *parents, leaf = key.split(".")
        for p in parents:
            if not isinstance(node.get(p), dict):
                raise ConfigError(f"unknown config section {p!r} in {key!r}")
            node = node[p]
        if leaf not in node:
            raise ConfigError(f"unknown key {key!r}; known keys here: {', '.join(sorted(node))}")
        node[leaf] = value
    return from_dict(type(cfg), table)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    raise ConfigError(f"cannot write {v!r} to TOML")


def to_toml(cfg: Any) -> str:
    """The resolved configuration as TOML text (None values are omitted: they mean default)."""
    lines: list[str] = []

    def emit(table: dict[str, Any], name: str) -> None:
        scalars = {k: v for k, v in table.items() if not isinstance(v, dict) and v is not None}
        if name and (scalars or not table):
            lines.append(f"\n[{name}]")
        lines.extend(f"{k} = {_toml_value(v)}" for k, v in scalars.items())
        for k, v in table.items():
            if isinstance(v, dict):
                emit(v, f"{name}.{k}" if name else k)

    emit(to_dict(cfg), "")
    return "\n".join(lines).lstrip() + "\n"
