"""Validated configuration: TOML files read into dataclasses.

Unknown keys and wrong types are errors that name the key with its full path
(e.g. ``behavior.weights.fringe``), so a typo in a mission file never passes
silently.
"""

from __future__ import annotations

import dataclasses
import tomllib
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")


class ConfigError(ValueError):
    """A configuration value or key is wrong; the message names it."""


class RangeError(ConfigError):
    """A value outside its bounds; keeps them so that a command-line flag can be named instead of the key."""

    def __init__(self, name: str, value: float, lo: float | None, hi: float | None) -> None:
        self.name, self.value, self.lo, self.hi = name, value, lo, hi
        super().__init__(f"{name} = {value} is out of range {self.bounds}")

    @property
    def bounds(self) -> str:
        return f"[{'-inf' if self.lo is None else self.lo}, {'inf' if self.hi is None else self.hi}]"

    def requirement(self) -> str:
        """``must be >= 20.0`` / ``must be in [20.0, 5000.0]``: the rule, without the key's name."""
        if self.hi is None:
            return f"must be >= {self.lo}"
        if self.lo is None:
            return f"must be <= {self.hi}"
        return f"must be in {self.bounds}"


def shipped_config(kind: str) -> Path:
    """``config/<kind>`` (behaviors, missions): the checkout's, else the copy a wheel installs beside ``_core``."""
    checkout = Path(__file__).resolve().parents[2] / "config" / kind
    if checkout.is_dir():
        return checkout
    from layerpilot import _core

    return Path(_core.__file__).resolve().parent / "config" / kind


def load_toml(path: str | Path) -> dict[str, Any]:
    path = Path(path)
    try:
        with path.open("rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise ConfigError(f"{path}: no such config file") from None
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: not valid TOML: {exc}") from None


def from_dict(cls: type[T], data: dict[str, Any], where: str) -> T:
    """Build dataclass ``cls`` from ``data``; nested dataclasses are built recursively.

    Values are checked against the field types (int, float, bool, str, tuples,
    lists, dicts, Optional, nested dataclasses); a dataclass may add range checks
    in ``__post_init__`` by raising ``ConfigError`` or ``ValueError``.
    """
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: expected a table, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(set(data) - set(fields))
    if unknown:
        raise ConfigError(f"{where}: unknown key(s) {', '.join(where + '.' + k for k in unknown)}; "
                          f"allowed: {', '.join(sorted(fields))}")
    kwargs = {name: _convert(hints[name], value, f"{where}.{name}") for name, value in data.items()}
    try:
        return cls(**kwargs)
    except TypeError as exc:  # a required field is missing
        raise ConfigError(f"{where}: {exc}") from None
    except ValueError as exc:
        if isinstance(exc, ConfigError):
            raise
        raise ConfigError(f"{where}: {exc}") from None


def _convert(tp: Any, value: Any, where: str) -> Any:
    origin = typing.get_origin(tp)
    args = typing.get_args(tp)
    if origin in (typing.Union, types.UnionType):
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _convert(arg, value, where)
            except ConfigError as exc:
                errors.append(str(exc))
        raise ConfigError(errors[0] if errors else f"{where}: invalid value {value!r}")
    if dataclasses.is_dataclass(tp):
        return from_dict(tp, value, where)
    if origin in (list, tuple):
        if not isinstance(value, (list, tuple)):
            raise ConfigError(f"{where}: expected a list, got {value!r}")
        if origin is tuple and args and args[-1] is not Ellipsis:
            if len(value) != len(args):
                raise ConfigError(f"{where}: expected {len(args)} values, got {len(value)}")
            return tuple(_convert(a, v, f"{where}[{i}]") for i, (a, v) in enumerate(zip(args, value)))
        item = args[0] if args else Any
        converted = [_convert(item, v, f"{where}[{i}]") for i, v in enumerate(value)]
        return tuple(converted) if origin is tuple else converted
    if origin is dict:
        if not isinstance(value, dict):
            raise ConfigError(f"{where}: expected a table, got {value!r}")
        kt, vt = args if args else (Any, Any)
        return {_convert(kt, k, where): _convert(vt, v, f"{where}.{k}") for k, v in value.items()}
    if tp is Any:
        return value
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: expected an integer, got {value!r}")
        return value
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: expected true or false, got {value!r}")
        return value
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: expected a string, got {value!r}")
        return value
    if typing.get_origin(tp) is typing.Literal:
        if value not in args:
            raise ConfigError(f"{where}: expected one of {', '.join(map(repr, args))}, got {value!r}")
        return value
    raise ConfigError(f"{where}: unsupported config type {tp!r}")


def check_range(name: str, value: float, lo: float | None = None, hi: float | None = None) -> None:
    """Raise ConfigError naming ``name`` unless lo <= value <= hi."""
    if not ((lo is None or value >= lo) and (hi is None or value <= hi)):  # NaN fails too
        raise RangeError(name, value, lo, hi)
