"""The range machinery of the configuration: the intervals every number must lie in, the checking
of each value read from YAML against its dataclass field, and the checks between keys.

:mod:`lapwrench.config` declares its sections with :func:`ranged` fields (``ranged("[lo, hi]",
default, why)``, brackets closed, parentheses open); :func:`build` turns a nested mapping into
those dataclasses, refusing unknown keys, wrong types, non-finite numbers and values outside their
range with a :class:`ConfigError` naming the dotted key. Kept apart from the sections so that the
rules of *how* a value is checked live in one place, and the sections read as data.

:func:`check_consistency` checks what no single range can: ordered pairs (ε1 < ε2, ...), the start pose
inside the envelope (:func:`check_depths`) and the RCM gains against the control rate's Euler step
(:func:`check_rcm_dynamics`).
"""

from __future__ import annotations

import dataclasses
import difflib
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


def suggestion(key: Any, known: typing.Iterable[str]) -> str:
    """`` (did you mean 'Kp'?)`` for a mistyped ``key`` close to one of ``known`` (case ignored), else ""."""
    by_lower = {k.lower(): k for k in known}
    close = difflib.get_close_matches(str(key)[:100].lower(), list(by_lower), n=1, cutoff=0.75)
    return f" (did you mean {by_lower[close[0]]!r}?)" if close else ""


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
            raise ConfigError(f"unknown config key {short(where)}{suggestion(key, fields)}; known keys here: "
                              f"{sorted(fields)}", where)
    kwargs = {}
    for name, f in fields.items():
        key = f"{prefix}.{name}" if prefix else name
        if name not in data:
            continue
        annotation = hints[name]
        if isinstance(annotation, type) and dataclasses.is_dataclass(annotation):  # a section: its class
            kwargs[name] = build(annotation, data[name], key)
        else:
            kwargs[name] = check_value(key, data[name], annotation, f.metadata.get("range"))
    return cls(**kwargs)


# -- checks between keys ----------------------------------------------------------------------------------------
# The lateral effective mass Λ = (J M⁻¹ Jᵀ)⁻¹ of the RCM task at p_R (J the lateral RCM task), over the shipped
# arms, their home poses ± 0.3 rad and lambda0 in [0.5, 0.95]: 0.19 kg (xarm7) to 4.3 kg (ur5); Panda 0.36-1.9 kg.
LIGHTEST_RCM_MASS = 0.15  # kg, below the lightest of them
RCM_SETTLING_TIME = 1.0  # s, slowest time constant allowed for the RCM error to decay
STOP_TICKS = 5  # motion.stop_time in control periods, at least


def require(ok: bool, key: str, message: str) -> None:
    """A :class:`ConfigError` naming ``key`` unless ``ok``."""
    if not ok:
        raise ConfigError(f"config key '{key}' {message}", key)


def check_consistency(cfg: Any) -> None:
    """Checks between the keys of a :class:`lapwrench.config.Config` (each key's own range is checked as it is
    read): pairs that must be ordered, the start pose inside the envelope, and the discrete-time dynamics."""
    t, a, s, c, env = cfg.tracking, cfg.adaptive_rcm, cfg.scope, cfg.camera, cfg.envelope
    require(t.epsilon2 > t.epsilon1, "tracking.epsilon2",
            f"({t.epsilon2}) must exceed 'tracking.epsilon1' ({t.epsilon1})")
    diagonal = math.hypot(c.width, c.height)
    require(t.F_sum_max >= t.F_max, "tracking.F_sum_max", f"({t.F_sum_max}) must be at least 'tracking.F_max' "
            f"({t.F_max}): one instrument alone must reach F_max")
    require(t.epsilon1 < diagonal, "tracking.epsilon1", f"({t.epsilon1} px) must be below the image diagonal "
            f"({diagonal:.0f} px), or no instrument ever leaves the dead zone")
    require(a.gamma2 > a.gamma1, "adaptive_rcm.gamma2", f"({a.gamma2}) must exceed 'adaptive_rcm.gamma1' ({a.gamma1})")
    require(c.u0 < c.width, "camera.u0", f"({c.u0}) must lie inside the image width (0, {c.width})")
    require(c.v0 < c.height, "camera.v0", f"({c.v0}) must lie inside the image height (0, {c.height})")
    require(s.handle_offset < s.length, "scope.handle_offset", "must be shorter than 'scope.length'")
    require(env.depth_min < env.depth_max, "envelope.depth_max",
            f"({env.depth_max}) must exceed 'envelope.depth_min' ({env.depth_min})")
    check_depths(cfg)
    check_rcm_dynamics(cfg)


def check_depths(cfg: Any) -> None:
    """The scope's insertion depths against its geometry.

    - The tip starts ``(1 - lambda0) L`` beyond the RCM point (eq 18 puts p_R at ``lambda0 L`` from {E}); outside
      ``[depth_min, depth_max]`` the supervisor holds on the first tick (it checks the measured depth against that
      range), so nothing could ever move: ``lambda0: 0.95`` starts at 14.5 mm, below the default 30 mm.
    - At ``depth_max`` the RCM point lies ``L - depth_max`` from {E}; the handle, ``handle_offset`` from {E}, must
      stay on the outside of it, or the envelope lets the hand push the handle into the incision.
    """
    s, env = cfg.scope, cfg.envelope
    start = (1.0 - s.lambda0) * s.length
    require(env.depth_min <= start <= env.depth_max, "scope.lambda0",
            f"({s.lambda0}) starts the tip {start * 1e3:.1f} mm beyond the RCM point ((1 - lambda0) x 'scope.length'), "
            f"outside the envelope's depth range [{env.depth_min * 1e3:.1f}, {env.depth_max * 1e3:.1f}] mm "
            "('envelope.depth_min', 'envelope.depth_max'): the supervisor would hold before anything moves")
    require(env.depth_max < s.length - s.handle_offset, "envelope.depth_max",
            f"({env.depth_max} m) must be shorter than 'scope.length' less 'scope.handle_offset' "
            f"({s.length - s.handle_offset:.3f} m): deeper, the handle enters the incision")


def check_rcm_dynamics(cfg: Any) -> None:
    """The RCM task and the brake as the 1 kHz (``robot.control_rate_hz``) integration of the virtual model sees them.

    Across the shaft the RCM error obeys Λ ë = -K_p e - K_d ė, Λ the task's effective mass (0.19-4.3 kg on the
    shipped arms, :data:`LIGHTEST_RCM_MASS`), integrated by Euler steps of dt = 1/rate (eq 1):

    - ``semi_implicit`` takes K_d at the new velocity; the step's spectral radius is below 1 iff
      dt² K_p < 4 Λ + 2 dt K_d. Required with half that margin at the lightest mass: dt² K_p <= 2 Λ + dt K_d
      (at 20 Hz, K_p 10000 and K_d 200 took a 4 mm error to 14 mm and a hold; at 2 Hz the paper's gains took a
      30 N push to 77 mm).
    - ``explicit`` takes K_d at the old velocity: stable iff dt K_d < 2 Λ and dt² K_p < 4 Λ - 2 dt K_d; required
      dt² K_p + dt K_d <= 2 Λ (K_d 2000 at 1 kHz ran the joints up to the limits and stopped the arm).
    - Overdamped, the slowest pole is about K_p / K_d: below 1/:data:`RCM_SETTLING_TIME` the RCM error lingers
      (K_p 300 with K_d 2000 left 2.6 of 4 mm after 3 s). The underdamped decay rate K_d / 2Λ is the range of
      ``rcm.Kd``.
    - The null-space brake ``a = -θ̇_null / stop_time`` is an explicit step: it rings at dt/stop_time > 1 and
      diverges beyond 2; ``motion.stop_time`` must span :data:`STOP_TICKS` control periods.
    """
    rate, rcm, m = cfg.robot.control_rate_hz, cfg.rcm, LIGHTEST_RCM_MASS
    dt = 1.0 / rate
    if cfg.motion.integrator == "explicit":
        ok, bound = dt * dt * rcm.Kp + dt * rcm.Kd <= 2.0 * m, "dt^2 Kp + dt Kd <= 2 x"
    else:
        ok, bound = dt * dt * rcm.Kp <= 2.0 * m + dt * rcm.Kd, "dt^2 Kp - dt Kd <= 2 x"
    require(ok, "robot.control_rate_hz",
            f"({rate:g} Hz) is too slow for 'rcm.Kp' ({rcm.Kp:g} N/m) and 'rcm.Kd' ({rcm.Kd:g} N s/m) with the "
            f"{cfg.motion.integrator} step: the RCM task's Euler step needs {bound} {m} kg (the lightest arm's "
            "mass at the RCM point), or the RCM error grows")
    require(rcm.Kp >= rcm.Kd / RCM_SETTLING_TIME, "rcm.Kp",
            f"({rcm.Kp:g} N/m) is too soft for 'rcm.Kd' ({rcm.Kd:g} N s/m): the RCM error decays at Kp/Kd = "
            f"{rcm.Kp / rcm.Kd:.3g}/s, slower than 1/{RCM_SETTLING_TIME:g} s; raise Kp to at least Kd x 1/s")
    stop = cfg.motion.stop_time
    require(stop * rate >= STOP_TICKS, "motion.stop_time",
            f"({stop:g} s) must span at least {STOP_TICKS} control periods of 'robot.control_rate_hz' ({rate:g} Hz), "
            f"{STOP_TICKS / rate:g} s: the null-space brake is an explicit step that rings or diverges when shorter")
