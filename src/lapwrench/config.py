"""Configuration: one YAML file, validated on load.

The defaults (``data/default.yaml``) are the paper's Sec. IV-A parameters. Loading checks every
key against these dataclasses: an unknown key, a wrong type, a non-positive gain or threshold,
or an inconsistent pair (epsilon2 <= epsilon1, gamma2 <= gamma1) raises :class:`ConfigError`
naming the key.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import yaml

Ramp = Literal["printed", "c1"]


class ConfigError(ValueError):
    """A configuration value is missing, unknown, of the wrong type or out of range."""


def _positive(**kw: Any) -> Any:
    return field(metadata={"check": "positive"}, **kw)


def _nonnegative(**kw: Any) -> Any:
    return field(metadata={"check": "nonnegative"}, **kw)


@dataclass(frozen=True)
class RobotConfig:
    kind: Literal["panda", "fr3"] = "panda"
    control_rate_hz: float = _positive(default=1000.0)
    limit_fraction: float = _positive(default=0.9)
    position_margin: float = _nonnegative(default=0.05)

    @property
    def dt(self) -> float:
        return 1.0 / self.control_rate_hz


@dataclass(frozen=True)
class ScopeConfig:
    length: float = _positive(default=0.29)
    lambda0: float = _positive(default=0.8)
    handle_offset: float = _nonnegative(default=0.04)
    oblique_angle_deg: float = _nonnegative(default=0.0)


@dataclass(frozen=True)
class InteractionConfig:
    k_H: float = _positive(default=2000.0)
    k_min: int = _nonnegative(default=3)
    contact_threshold: int = _nonnegative(default=0)
    force_range: float = _positive(default=200.0)
    torque_range: float = _positive(default=10.0)


@dataclass(frozen=True)
class CameraConfig:
    width: int = _positive(default=640)
    height: int = _positive(default=480)
    fx: float = _positive(default=506.57)
    fy: float = _positive(default=506.72)
    u0: float = _positive(default=312.22)
    v0: float = _positive(default=243.39)


@dataclass(frozen=True)
class TrackingConfig:
    epsilon1: float = _positive(default=50.0)
    epsilon2: float = _positive(default=200.0)
    F_max: float = _positive(default=10.0)
    ramp: Ramp = "printed"
    direction: Literal["printed", "image_plane"] = "image_plane"


@dataclass(frozen=True)
class RcmConfig:
    Kp: float = _positive(default=300.0)
    Kd: float = _positive(default=20.0)


@dataclass(frozen=True)
class AdaptiveRcmConfig:
    """Eq (18)-(26) and the motion gate of the estimate-driven term (see :mod:`lapwrench.rcm.adaptive`).

    ``gate: speed`` weights the -α F_re⊥ term of eq (24) by w ∈ [0, 1], which falls from 1 at
    ``gate_soft`` x a threshold to 0 at the threshold, for each of the scope's pivot angular speed,
    flange linear speed and their (filtered) accelerations; w re-opens over ``gate_release_time``.
    ``gate: none`` is the paper's law as printed (w = 1 always).
    """

    enabled: bool = True
    F_op: float = _positive(default=10.0)
    gamma1: float = _positive(default=5.0)
    gamma2: float = _positive(default=15.0)
    ramp: Ramp = "printed"
    alpha: float = _positive(default=0.003)
    beta: float = _positive(default=0.05)
    epsilon: float = _positive(default=5e-4)
    gate: Literal["speed", "none"] = "speed"
    gate_angular_speed: float = _positive(default=0.2)  # rad/s, |P ω_E|: no adaptation above
    gate_linear_speed: float = _positive(default=0.1)  # m/s, |v_E| of the flange: no adaptation above
    gate_angular_acceleration: float = _positive(default=2.0)  # rad/s^2, filtered |P ω̇_E|: no adaptation above
    gate_linear_acceleration: float = _positive(default=2.0)  # m/s^2, filtered |v̇_E|: no adaptation above
    gate_soft: float = _nonnegative(default=0.5)  # fraction of each threshold where w starts to fall (1: hard gate)
    gate_filter_time: float = _nonnegative(default=0.02)  # s, time constant of the acceleration filter
    gate_release_time: float = _nonnegative(default=0.1)  # s, w re-opens from 0 to 1 at most this fast

    def __post_init__(self) -> None:
        if not self.gate_soft <= 1.0:
            raise ConfigError(f"config key 'adaptive_rcm.gate_soft' must lie in [0, 1], got {self.gate_soft}")
        if self.gate == "speed" and self.gate_soft * self.gate_linear_speed < self.alpha * self.F_op:
            # p_R moves at up to α F_op and the scope follows it: the gate must not throttle that motion
            raise ConfigError(
                f"config key 'adaptive_rcm.gate_linear_speed' x 'gate_soft' ({self.gate_soft * self.gate_linear_speed}"
                f" m/s) must be at least alpha x F_op ({self.alpha * self.F_op} m/s), the fastest adaptation"
            )


@dataclass(frozen=True)
class ViscousConfig:
    k_t: float = _positive(default=150.0)
    k_f: float = _positive(default=150.0)  # N s/m; the paper prints 2 (README, "damping")
    k_t_unguided: float = _positive(default=2.0)  # N m s, k_t while no hand grips the handle (tracking alone)


@dataclass(frozen=True)
class MotionConfig:
    integrator: Literal["semi_implicit", "explicit"] = "semi_implicit"
    self_motion_damping: float = _nonnegative(default=10.0)
    rcm_task: Literal["lateral", "printed"] = "lateral"
    joint_limit_zone: float = _nonnegative(default=0.3)  # rad inside each joint limit where self-motion pushes away
    joint_limit_stiffness: float = _nonnegative(default=5.0)  # N m/rad of that push (0: off)
    stop_time: float = _positive(default=0.1)  # s, time constant of the null-space brake when the RCM cannot be kept


@dataclass(frozen=True)
class EnvelopeConfig:
    """Task-space envelope of the scope (issue 9), enforced by scaling lower-priority motion.

    Speeds are those of the scope about/along the RCM point; depth is the distance of the tip
    beyond the RCM point along the shaft; roll is the rotation about the shaft from the start
    pose. Each wall is approached at most at its deceleration, so the hand meets a soft wall.
    """

    enabled: bool = True
    pivot_speed_max: float = _positive(default=0.5)  # rad/s, angular speed of the shaft about p_R
    pivot_deceleration: float = _positive(default=4.0)  # rad/s^2
    insertion_speed_max: float = _positive(default=0.05)  # m/s along the shaft
    insertion_deceleration: float = _positive(default=0.5)  # m/s^2
    depth_min: float = _positive(default=0.03)  # m of scope beyond p_R
    depth_max: float = _positive(default=0.12)  # m of scope beyond p_R
    roll_range: float = _positive(default=1.5708)  # rad, |roll| about the shaft from the start pose
    roll_speed_max: float = _positive(default=1.0)  # rad/s


@dataclass(frozen=True)
class SafetyConfig:
    """Bounds the safety supervisor checks on *measured* state; each one holds the arm with an alarm."""

    max_rcm_error: float = _positive(default=0.005)  # m, p_R to the scope axis at the measured joints
    depth_tolerance: float = _nonnegative(default=0.005)  # m beyond the envelope's depth range
    max_residual_force: float = _positive(default=20.0)  # N, |ΔF| (eq 19): the scope's force on the wall
    residual_force_time: float = _nonnegative(default=0.05)  # s |ΔF| must stay over its bound (estimate lag)


@dataclass(frozen=True)
class InputsConfig:
    max_rcm_error: float = _positive(default=0.02)
    max_image_age: float = _positive(default=0.2)
    max_instruments: int = _positive(default=8)  # more detections in one frame are a detector fault: none used


@dataclass(frozen=True)
class Config:
    robot: RobotConfig = field(default_factory=RobotConfig)
    scope: ScopeConfig = field(default_factory=ScopeConfig)
    interaction: InteractionConfig = field(default_factory=InteractionConfig)
    camera: CameraConfig = field(default_factory=CameraConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    rcm: RcmConfig = field(default_factory=RcmConfig)
    adaptive_rcm: AdaptiveRcmConfig = field(default_factory=AdaptiveRcmConfig)
    viscous: ViscousConfig = field(default_factory=ViscousConfig)
    motion: MotionConfig = field(default_factory=MotionConfig)
    inputs: InputsConfig = field(default_factory=InputsConfig)
    envelope: EnvelopeConfig = field(default_factory=EnvelopeConfig)
    safety: SafetyConfig = field(default_factory=SafetyConfig)

    def replace(self, **sections: dict[str, Any]) -> Config:
        """A copy with some values changed, e.g. ``cfg.replace(tracking={"ramp": "c1"})``; validated."""
        data = to_dict(self)
        for section, values in sections.items():
            if section not in data:
                raise ConfigError(f"unknown config section '{section}'")
            data[section].update(values)
        return from_dict(data)


def _check_value(key: str, value: Any, annotation: Any, check: str | None) -> Any:
    origin = typing.get_origin(annotation)
    if origin is Literal:
        allowed = typing.get_args(annotation)
        if value not in allowed:
            raise ConfigError(f"config key '{key}' must be one of {list(allowed)}, got {value!r}")
        return value
    if annotation is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"config key '{key}' must be true or false, got {value!r}")
        return value
    if annotation is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"config key '{key}' must be an integer, got {value!r}")
    elif annotation is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"config key '{key}' must be a number, got {value!r}")
        value = float(value)
        if not math.isfinite(value):
            raise ConfigError(f"config key '{key}' must be finite, got {value!r}")
    if check == "positive" and not value > 0:
        raise ConfigError(f"config key '{key}' must be positive, got {value!r}")
    if check == "nonnegative" and not value >= 0:
        raise ConfigError(f"config key '{key}' must be non-negative, got {value!r}")
    return value


def _build(cls: type, data: Any, prefix: str) -> Any:
    if not isinstance(data, dict):
        raise ConfigError(f"config section '{prefix or 'root'}' must be a mapping, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    fields = {f.name: f for f in dataclasses.fields(cls)}
    for key in data:
        if key not in fields:
            where = f"{prefix}.{key}" if prefix else str(key)
            raise ConfigError(f"unknown config key '{where}'; known keys here: {sorted(fields)}")
    kwargs = {}
    for name, f in fields.items():
        key = f"{prefix}.{name}" if prefix else name
        if name not in data:
            continue
        annotation = hints[name]
        if dataclasses.is_dataclass(annotation):
            kwargs[name] = _build(annotation, data[name], key)
        else:
            kwargs[name] = _check_value(key, data[name], annotation, f.metadata.get("check"))
    return cls(**kwargs)


def _check_consistency(cfg: Config) -> None:
    if cfg.tracking.epsilon2 <= cfg.tracking.epsilon1:
        raise ConfigError(
            f"config key 'tracking.epsilon2' ({cfg.tracking.epsilon2}) must exceed "
            f"'tracking.epsilon1' ({cfg.tracking.epsilon1})"
        )
    if cfg.adaptive_rcm.gamma2 <= cfg.adaptive_rcm.gamma1:
        raise ConfigError(
            f"config key 'adaptive_rcm.gamma2' ({cfg.adaptive_rcm.gamma2}) must exceed "
            f"'adaptive_rcm.gamma1' ({cfg.adaptive_rcm.gamma1})"
        )
    if not cfg.scope.lambda0 < 1.0:
        raise ConfigError(f"config key 'scope.lambda0' must lie in (0, 1), got {cfg.scope.lambda0}")
    if not cfg.scope.handle_offset < cfg.scope.length:
        raise ConfigError("config key 'scope.handle_offset' must be shorter than 'scope.length'")
    if not cfg.scope.oblique_angle_deg < 90.0:
        raise ConfigError("config key 'scope.oblique_angle_deg' must be below 90")
    env = cfg.envelope
    if not env.depth_min < env.depth_max:
        raise ConfigError(
            f"config key 'envelope.depth_max' ({env.depth_max}) must exceed 'envelope.depth_min' ({env.depth_min})"
        )
    if not env.depth_max < cfg.scope.length:
        raise ConfigError("config key 'envelope.depth_max' must be shorter than 'scope.length'")
    if not env.roll_range <= math.pi:
        raise ConfigError(f"config key 'envelope.roll_range' must lie in (0, pi], got {env.roll_range}")
    if not cfg.robot.limit_fraction <= 1.0:
        raise ConfigError(f"config key 'robot.limit_fraction' must lie in (0, 1], got {cfg.robot.limit_fraction}")


def ensure_writable_dir(path: str | Path) -> Path:
    """Create ``path`` if needed and check that files can be written there (OSError if not)."""
    out = Path(path)
    out.mkdir(parents=True, exist_ok=True)
    probe = out / ".write-test"
    probe.write_text("ok")
    probe.unlink()
    return out


def from_dict(data: dict[str, Any]) -> Config:
    """Validate a nested mapping and build a :class:`Config` (missing keys take the defaults)."""
    cfg = _build(Config, data, "")
    _check_consistency(cfg)
    return cfg


def to_dict(cfg: Config) -> dict[str, Any]:
    return dataclasses.asdict(cfg)


def presets() -> list[str]:
    """Names of the packaged presets (``data/presets/*.yaml``), usable wherever a config path is."""
    folder = resources.files("lapwrench").joinpath("data/presets")
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


def load(path: str | Path | None = None) -> Config:
    """Load a YAML configuration file or a packaged preset name; ``None`` gives the defaults.

    Keys missing from the file keep their defaults (the paper's parameters).
    """
    if path is None:
        text = resources.files("lapwrench").joinpath("data/default.yaml").read_text()
        source = "default.yaml"
    else:
        p = Path(path)
        if not p.is_file() and str(path) in presets():
            p = Path(str(resources.files("lapwrench").joinpath(f"data/presets/{path}.yaml")))
        if not p.is_file():
            raise ConfigError(f"config file not found: {path} (presets: {', '.join(presets())})")
        text = p.read_text()
        source = str(path)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ConfigError(f"{source} is not valid YAML: {exc}") from exc
    if data is None:
        data = {}
    try:
        return from_dict(data)
    except ConfigError as exc:
        raise ConfigError(f"{source}: {exc}") from exc


def dump(cfg: Config, path: str | Path) -> None:
    Path(path).write_text(yaml.safe_dump(to_dict(cfg), sort_keys=False))


