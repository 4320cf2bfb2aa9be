"""Parameter spaces of studies and tuning runs: where a swept key lands, and how a value is drawn.

A study varies three kinds of key, all written the same way in YAML:

- ``<section>.<key>`` (and ``cues.<name>.<key>``): a configuration value, checked by the config's own
  validation (:func:`lapwrench.config.from_dict`), so the envelope and supervisor bounds are sweepable
  like any gain;
- ``world.<field>``: a :class:`~lapwrench.sim.variation.WorldVariation` field (surgeon, trocar,
  incision shift, detector);
- ``robot``: the simulated arm (``robot.kind``).

A random key is a :class:`Dist`: ``{uniform: [a, b]}``, ``{loguniform: [a, b]}``, ``{normal: [mean, sd]}``
(optionally with ``min``/``max``), ``{integer: [a, b]}`` (both ends included) or ``{choice: [...]}``.
"""

from __future__ import annotations

import copy
import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from lapwrench import config as config_mod
from lapwrench.config_yaml import short
from lapwrench.sim.variation import WorldVariation

WORLD_PREFIX = "world."
ROBOT_KEY = "robot"
KINDS = ("uniform", "loguniform", "normal", "integer", "choice")
# How far out an unclipped normal draw is checked, in standard deviations: numpy draws beyond it with
# probability below 1e-23, so a side that passes here never yields a refused value.
NORMAL_REACH_SD = 10.0


class SpaceError(ValueError):
    """A parameter key or value that cannot be applied; the message names the key."""


def is_number(x: object) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and math.isfinite(x)


@dataclass(frozen=True)
class Dist:
    """One random parameter: its kind and arguments (see the module docstring)."""

    kind: str
    args: tuple[Any, ...]
    low: float | None = None  # clip (normal only)
    high: float | None = None

    def draw(self, rng: np.random.Generator) -> Any:
        """One value drawn with ``rng``."""
        a = self.args
        if self.kind == "choice":
            return a[int(rng.integers(len(a)))]
        if self.kind == "integer":
            return int(rng.integers(int(a[0]), int(a[1]) + 1))
        if self.kind == "uniform":
            return float(rng.uniform(a[0], a[1]))
        if self.kind == "loguniform":
            return float(math.exp(rng.uniform(math.log(a[0]), math.log(a[1]))))
        low = -math.inf if self.low is None else self.low
        high = math.inf if self.high is None else self.high
        return float(np.clip(rng.normal(a[0], a[1]), low, high))

    def corners(self) -> tuple[Any, ...]:
        """Values that bound what :meth:`draw` returns, to validate before anything runs."""
        if self.kind == "choice":
            return self.args
        if self.kind == "normal":
            return tuple(x for x in (self.low, self.high, self.args[0]) if x is not None)
        return (self.args[0], self.args[1])

    def to_tune(self) -> Any:
        """The same distribution in Ray Tune's search-space API."""
        from ray import tune

        a = self.args
        if self.kind == "choice":
            return tune.choice(list(a))
        if self.kind == "integer":
            return tune.randint(int(a[0]), int(a[1]) + 1)
        if self.kind == "uniform":
            return tune.uniform(a[0], a[1])
        if self.kind == "loguniform":
            return tune.loguniform(a[0], a[1])
        return tune.sample_from(lambda _: Dist.draw(self, np.random.default_rng()))


def parse_dist(key: str, spec: Any) -> Dist:
    """A :class:`Dist` from its YAML mapping; SpaceError naming ``key`` if malformed."""
    if not isinstance(spec, dict):
        raise SpaceError(f"'{key}' must be a mapping such as {{uniform: [0.8, 1.2]}}, got {short(spec)}")
    kinds = [k for k in spec if k in KINDS]
    extra = sorted((set(spec) - set(KINDS) - {"min", "max"}), key=str)
    if len(kinds) != 1 or extra:
        raise SpaceError(f"'{key}' needs exactly one of {', '.join(KINDS)} (and min/max for normal), got {short(spec)}")
    kind = kinds[0]
    args = spec[kind]
    if not isinstance(args, list) or not args:
        raise SpaceError(f"'{key}': {kind} takes a list, got {short(args)}")
    if kind != "normal" and ("min" in spec or "max" in spec):
        raise SpaceError(f"'{key}': min/max apply to normal only")
    if kind == "choice":
        return Dist(kind, tuple(args))
    if len(args) != 2 or not all(is_number(x) for x in args):
        raise SpaceError(f"'{key}': {kind} takes two finite numbers, got {short(args)}")
    a, b = (float(x) for x in args)
    if kind == "normal":
        low, high = spec.get("min"), spec.get("max")
        for name, v in (("min", low), ("max", high)):
            if v is not None and not is_number(v):
                raise SpaceError(f"'{key}': normal {name} must be a finite number, got {short(v)}")
        if b <= 0 or (low is not None and high is not None and low >= high):
            raise SpaceError(f"'{key}': normal needs sd > 0 and min < max, got {short(spec)}")
        return Dist(kind, (a, b), None if low is None else float(low), None if high is None else float(high))
    if not a < b:
        raise SpaceError(f"'{key}': {kind} needs low < high, got {short(args)}")
    if kind == "loguniform" and a <= 0:
        raise SpaceError(f"'{key}': loguniform needs low > 0, got {a:g}")
    if not math.isfinite(b - a) or (kind == "integer" and max(abs(a), abs(b)) > 2**53):
        raise SpaceError(f"'{key}': {kind} range too wide to draw from, got {short(args)}")
    if kind == "integer":
        if not (float(a).is_integer() and float(b).is_integer()):
            raise SpaceError(f"'{key}': integer takes two whole numbers, got {short(args)}")
        return Dist(kind, (int(a), int(b)))
    return Dist(kind, (a, b))


def _set_path(data: dict[str, Any], key: str, value: Any) -> None:
    parts = key.split(".")
    node: Any = data
    for i, part in enumerate(parts[:-1]):
        if not isinstance(node, dict) or part not in node:
            raise SpaceError(f"'{key}' is not a configuration key ('{'.'.join(parts[: i + 1])}' does not exist)")
        node = node[part]
    if not isinstance(node, dict) or parts[-1] not in node or isinstance(node[parts[-1]], dict):
        raise SpaceError(f"'{key}' is not a configuration key")
    node[parts[-1]] = list(value) if isinstance(value, tuple) else value


def apply(base: config_mod.Config, params: dict[str, Any]) -> tuple[config_mod.Config, WorldVariation]:
    """The configuration and world of one point of the space; SpaceError naming the key if a value is
    refused (by the config's own validation or the world's)."""
    data = copy.deepcopy(config_mod.to_dict(base))
    world: dict[str, Any] = {}
    for key, value in params.items():
        if key.startswith(WORLD_PREFIX):
            world[key[len(WORLD_PREFIX):]] = value
        else:
            _set_path(data, "robot.kind" if key == ROBOT_KEY else key, value)
    try:
        cfg = config_mod.from_dict(data)
    except config_mod.ConfigError as exc:
        raise SpaceError(str(exc)) from exc
    try:
        variation = WorldVariation.from_dict(world)
    except (TypeError, ValueError) as exc:
        raise SpaceError(str(exc)) from exc
    return cfg, variation


def check_key(base: config_mod.Config, key: str, values: tuple[Any, ...]) -> list[str]:
    """Apply each of ``values`` to ``key`` alone: a bad key or value fails here, before any run.
    Returns what each value resolves to (the configuration and world as sorted JSON), so two values
    that mean the same (100 and 100.0) can be told apart from two that differ."""
    if not isinstance(key, str) or not key:
        raise SpaceError(f"parameter keys are dotted names such as viscous.k_t, got {short(key)}")
    resolved = []
    for v in values:
        try:
            cfg, world = apply(base, {key: v})
        except SpaceError as exc:
            raise SpaceError(f"'{key}' = {short(v)}: {exc}") from exc
        resolved.append(json.dumps([config_mod.to_dict(cfg), world.to_dict()], sort_keys=True, default=str))
    return resolved


def check_dist(base: config_mod.Config, key: str, dist: Dist) -> None:
    """Check every value ``dist`` can draw for ``key`` before anything runs: its corners (see
    :meth:`Dist.corners`), and for a normal, how far it reaches on a side left without ``min``/``max``.
    A key with a range (a gain that must stay > 0, say) needs the clip there, or a draw beyond it would
    fail a job (a sweep) or drop a trial (tune) halfway through. SpaceError naming the key otherwise."""
    check_key(base, key, dist.corners())
    if dist.kind != "normal":
        return
    mean, sd = dist.args
    for side, bound, reach in (("min", dist.low, mean - NORMAL_REACH_SD * sd),
                               ("max", dist.high, mean + NORMAL_REACH_SD * sd)):
        if bound is not None:
            continue
        try:
            apply(base, {key: reach})
        except SpaceError as exc:
            detail = " ".join(str(exc).split())
            detail = detail if len(detail) <= 200 else detail[:197] + "..."
            raise SpaceError(f"'{key}': normal {short(list(dist.args))} without {side} can draw {reach:.6g}, "
                             f"which is refused ({detail}); give it a {side} inside the key's range") from exc
