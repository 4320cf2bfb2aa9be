"""The range machinery of the configuration: the intervals every number must lie in, and the checking
of each value read from YAML against its dataclass field.

:mod:`lapwrench.config` declares its sections with :func:`ranged` fields (``ranged("[lo, hi]",
default, why)``, brackets closed, parentheses open); :func:`build` turns a nested mapping into
those dataclasses, refusing unknown keys, wrong types, non-finite numbers and values outside their
range with a :class:`ConfigError` naming the dotted key. Kept apart from the sections so that the
rules of *how* a value is checked live in one place, and the sections read as data.
"""

from __future__ import annotations

import dataclasses
import math
import re
import typing
from dataclasses import dataclass, field
from typing import Any, Literal

from lapwrench.config_yaml import short


class ConfigError(ValueError):
    """A configuration value is missing, unknown, of the wrong type or out of range.

    ``key`` is the dotted key path the error is about (``"rcm.Kp"``), when there is one.
    """

    def __init__(self, message: str, key: str | None = None) -> None:
        super().__init__(message)
        self.key = key


@dataclass(frozen=True)
class Range:
    """An interval ``lo .. hi`` with open or closed ends, and why a value must lie in it."""

    lo: float
    hi: float
    lo_open: bool
    hi_open: bool
    why: str = ""

    def __contains__(self, x: float) -> bool:
        above = x > self.lo if self.lo_open else x >= self.lo
        below = x < self.hi if self.hi_open else x <= self.hi
        return above and below

    def __str__(self) -> str:
        return f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"


_INTERVAL = re.compile(r"^\s*([\[(])\s*([^,\s]+)\s*,\s*([^,\s]+)\s*([\])])\s*$")


def interval(spec: str, why: str) -> Range:
    """Parse ``"(0, 1]"``-style interval notation (``pi`` allowed as a bound)."""
    m = _INTERVAL.match(spec)
    if m is None:
        raise ValueError(f"bad interval {spec!r}")
    lo, hi = (math.pi if b == "pi" else float(b) for b in (m[2], m[3]))
    return Range(lo, hi, m[1] == "(", m[4] == ")", why)


def ranged(spec: str, default: Any, why: str = "") -> Any:
    """A dataclass field whose value must lie in ``spec`` (interval notation); ``why`` says why."""
    return field(default=default, metadata={"range": interval(spec, why)})


def number(key: str, value: Any, annotation: Any) -> int | float:
    """``value`` as the int or (finite) float the field's annotation asks for."""
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"config key '{key}' must be an integer, got {short(value)}", key)
        return value
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ConfigError(f"config key '{key}' must be a number, got {short(value)}", key)
    try:
        number = float(value)
    except OverflowError:  # an int beyond ~1.8e308
        raise ConfigError(f"config key '{key}' is too large, got {short(value)}", key) from None
    if not math.isfinite(number):
        raise ConfigError(f"config key '{key}' must be finite, got {short(value)}", key)
    return number


def check_value(key: str, value: Any, annotation: Any, bounds: Range | None) -> Any:
    origin = typing.get_origin(annotation)
    if origin is Literal:
        allowed = typing.get_args(annotation)
        if not isinstance(value, str | bool | int | float) or value not in allowed:
            raise ConfigError(f"config key '{key}' must be one of {list(allowed)}, got {short(value)}", key)
        return value
    if annotation is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"config key '{key}' must be true or false, got {short(value)}", key)
        return value
    if annotation is str:
        if not isinstance(value, str):
            raise ConfigError(f"config key '{key}' must be text, got {short(value)}", key)
        return value
    if origin is tuple:
        return _numbers(key, value, typing.get_args(annotation), bounds)
    value = number(key, value, annotation)
    if bounds is not None and value not in bounds:
        why = f" ({bounds.why})" if bounds.why else ""
        raise ConfigError(f"config key '{key}' must lie in {bounds}{why}, got {short(value)}", key)
    return value


def _numbers(key: str, value: Any, args: tuple[Any, ...], bounds: Range | None) -> tuple[Any, ...]:
    """A list of numbers for a ``tuple[float, ...]`` (any length but at least one) or a fixed-length
    ``tuple[float, float, float]`` field; each element checked against the field's range."""
    variadic = len(args) == 2 and args[1] is Ellipsis
    if not isinstance(value, list | tuple) or (not variadic and len(value) != len(args)) or not value:
        size = "one or more numbers" if variadic else f"{len(args)} numbers"
        raise ConfigError(f"config key '{key}' must be a list of {size}, got {short(value)}", key)
    kinds = [args[0]] * len(value) if variadic else list(args)
    return tuple(check_value(f"{key}[{i}]", v, t, bounds) for i, (v, t) in enumerate(zip(value, kinds, strict=True)))


def build(cls: type, data: Any, prefix: str) -> Any:
    if not isinstance(data, dict):
        raise ConfigError(
            f"config section '{prefix or 'root'}' must be a mapping, got {type(data).__name__}", prefix or None
        )
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for key in data:
        if key not in fields:
            where = f"{prefix}.{key}" if prefix else str(key)
            raise ConfigError(f"unknown config key {short(where)}; known keys here: {sorted(fields)}", where)
    kwargs = {}
    for name, f in fields.items():
        key = f"{prefix}.{name}" if prefix else name
        if name not in data:
            continue
        annotation = hints[name]
        if dataclasses.is_dataclass(annotation):
            kwargs[name] = build(annotation, data[name], key)
        else:
            kwargs[name] = check_value(key, data[name], annotation, f.metadata.get("range"))
    return cls(**kwargs)
