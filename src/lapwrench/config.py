"""Configuration: one YAML file, validated on load.

The defaults (``data/default.yaml``) are the paper's Sec. IV-A parameters. Loading checks every
key against these dataclasses: an unknown key, a wrong type, a value outside its physical range
or an inconsistent pair (epsilon2 <= epsilon1, u0 outside the image, ...) raises
:class:`ConfigError` naming the key (and, from a file, its line).

Every number has a range (``ranged("[lo, hi]", default, why)``, brackets closed, parentheses
open) chosen from what makes physical sense for the Franka arm, the 64-element tactile handle and a
laparoscope; the ``why`` text is shown in the error. The file itself is read by
:mod:`lapwrench.config_yaml`: at most 1 MiB of UTF-8, no aliases or anchors, no duplicate keys.
The ranges, the checking of each value read and the checks between keys (start depth inside the
envelope, RCM gains against the control rate, ...) live in :mod:`lapwrench.config_ranges`; this
module holds the sections and loading/saving.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any, Literal

import yaml

from lapwrench import config_yaml
from lapwrench.config_cues import DEFAULT_CUES, CueEntry, cues_to_dict, parse_cues
from lapwrench.config_ranges import ConfigError, build, check_consistency, ranged
from lapwrench.config_ranges import Range as Range  # re-exported: a field's metadata["range"]
from lapwrench.config_yaml import short
from lapwrench.robot_kinds import NOT_SHIPPED, ROBOT_KINDS, unknown_kind_message

Ramp = Literal["printed", "c1"]
TactileChecksum = Literal["none", "sum8", "xor8", "crc16-modbus"]

TACTILE_ELEMENTS = 64  # elements of the handle's grip array (lapwrench.sensors.TACTILE_ELEMENTS)
TACTILE_MAX_VALUE = 255  # largest element reading


@dataclass(frozen=True)
class RobotConfig:
    kind: str = "panda"  # a shipped arm: lapwrench.robot_kinds.ROBOT_KINDS (its spec: lapwrench.robot.arms)
    # the `run` and `demo` commands further require 1000 (the Franka differentiates over 1 ms)
    control_rate_hz: float = ranged("[1, 10000]", 1000.0, "Hz, a control rate")
    limit_fraction: float = ranged("[0.05, 1]", 0.9, "fraction of the Franka limits; below 5% the arm barely moves")
    position_margin: float = ranged("[0, 0.5]", 0.05, "rad; more would shrink some Franka joint ranges to nothing")

    def __post_init__(self) -> None:
        if self.kind in NOT_SHIPPED:
            raise ConfigError(f"config key 'robot.kind': {unknown_kind_message(self.kind)}", "robot.kind")
        if self.kind not in ROBOT_KINDS:
            raise ConfigError(
                f"config key 'robot.kind' must be one of {list(ROBOT_KINDS)}, got {short(self.kind)}", "robot.kind"
            )

    @property
    def dt(self) -> float:
        return 1.0 / self.control_rate_hz


@dataclass(frozen=True)
class ScopeConfig:
    length: float = ranged("[0.1, 0.6]", 0.29, "m, laparoscopes are 0.1-0.6 m long")
    lambda0: float = ranged("(0, 1)", 0.8, "fraction of the scope length where the RCM point starts")
    handle_offset: float = ranged("[0, 0.5]", 0.04, "m along the shaft, and shorter than scope.length")
    oblique_angle_deg: float = ranged("[0, 90)", 0.0, "degrees of view angle off the shaft (0, 30, 45, 70)")
    # The grip: the part of the handle beyond the F/T sensor, whose weight the sensor reads on top of the
    # hand (lapwrench.wrenches.grip_weight; `lapwrench identify-grip` fits both from a run's log)
    grip_mass: float = ranged("[0, 2]", 0.1, "kg beyond the handle's F/T sensor; 0: none")
    grip_com: tuple[float, float, float] = ranged("[-0.2, 0.2]", (0.0, 0.0, 0.01), "m, in {H}, from the F/T sensor")


@dataclass(frozen=True)
class InteractionConfig:
    k_H: float = ranged("[200, 100000]", 2000.0, "delta = sum(Se)/k_H; below 200 a full grip gives delta > 80")
    k_min: int = ranged(f"[0, {TACTILE_ELEMENTS - 1}]", 3, "contacts needed: n_c > k_min of the 64 elements")
    contact_threshold: int = ranged(
        f"[0, {TACTILE_MAX_VALUE - 1}]", 0, "an element reads 0..255; at 255 nothing ever counts as contact"
    )
    force_range: float = ranged("[1, 2000]", 200.0, "N, an F/T sensor's measuring range (HEX-E: 200)")
    torque_range: float = ranged("[0.1, 200]", 10.0, "N m, an F/T sensor's measuring range (HEX-E: 10)")
    # the F/T's zero follows its reading while nobody touches the grip (lapwrench.wrenches.ft_zero)
    auto_zero_time: float = ranged("[0, 600]", 2.0, "s, time constant of the untouched F/T's zero; 0: off")


@dataclass(frozen=True)
class CameraConfig:
    width: int = ranged("[16, 8192]", 640, "pixels")
    height: int = ranged("[16, 8192]", 480, "pixels")
    fx: float = ranged("[10, 100000]", 506.57, "pixels, a focal length")
    fy: float = ranged("[10, 100000]", 506.72, "pixels, a focal length")
    u0: float = ranged("(0, 8192)", 312.22, "pixels, inside the image width")
    v0: float = ranged("(0, 8192)", 243.39, "pixels, inside the image height")


@dataclass(frozen=True)
class TrackingConfig:
    epsilon1: float = ranged("(0, 12000)", 50.0, "pixels, inside the image diagonal")
    epsilon2: float = ranged("(0, 12000]", 200.0, "pixels, beyond epsilon1")
    F_max: float = ranged("(0, 50]", 10.0, "N, about what a hand pushes a scope with")
    # eq 8 sums over the detections: the sum is capped, so the force never grows with their number
    F_sum_max: float = ranged("(0, 100]", 20.0, "N, cap on the summed tracking force (two ports: 2 x F_max)")
    ramp: Ramp = "printed"
    direction: Literal["printed", "image_plane"] = "image_plane"


@dataclass(frozen=True)
class RcmConfig:
    Kp: float = ranged("(0, 10000]", 300.0, "N/m: 10 N at 1 mm; stiffer rings through the arm's admittance")
    # below 10 the RCM error of a 5 kg arm (the UR5's lateral mass at p_R) decays slower than 2 m/K_d = 1 s
    Kd: float = ranged("[10, 2000]", 20.0, "N s/m; below, the RCM error decays slower than 1 s; above, the solve fails")
    # cancel the velocity-product terms (J̇_R θ̇, Coriolis) of the RCM error's dynamics; eq (2) has none
    # (false): near a singularity they pushed the RCM error to 5-8 mm (README, "RCM feed-forward")
    feedforward: bool = True


@dataclass(frozen=True)
class AdaptiveRcmConfig:
    """Eq (18)-(26) and the motion gate of the estimate-driven term (see :mod:`lapwrench.rcm.adaptive`).

    ``gate: speed`` weights the -α F_re⊥ term of eq (24) by w ∈ [0, 1], which falls from 1 at
    ``gate_soft`` x a threshold to 0 at the threshold, for each of the scope's pivot angular speed,
    flange linear speed and their (filtered) accelerations; w re-opens over ``gate_release_time``.
    ``gate: none`` is the paper's law as printed (w = 1 always).
    """

    enabled: bool = True
    F_op: float = ranged("(0, 100]", 10.0, "N, saturation of the mapped residual force")
    gamma1: float = ranged("(0, 100]", 5.0, "N, dead zone of the residual force")
    gamma2: float = ranged("(0, 200]", 15.0, "N, saturation of the residual force, beyond gamma1")
    ramp: Ramp = "printed"
    alpha: float = ranged("(0, 0.05]", 0.003, "m/(N s); alpha F_op is how fast the RCM point moves")
    beta: float = ranged("(0, 10]", 0.05, "1/s, leakage to the anchor")
    epsilon: float = ranged("(0, 0.1]", 5e-4, "m/s, anchor update threshold")
    gate: Literal["speed", "none"] = "speed"
    # no adaptation above each of these (the Franka's flange moves at most ~2 m/s)
    gate_angular_speed: float = ranged("(0, 10]", 0.2, "rad/s, |P ω_E|")
    gate_linear_speed: float = ranged("(0, 2]", 0.1, "m/s, |v_E| of the flange")
    gate_angular_acceleration: float = ranged("(0, 100]", 2.0, "rad/s^2, filtered |P ω̇_E|")
    gate_linear_acceleration: float = ranged("(0, 50]", 2.0, "m/s^2, filtered |v̇_E|")
    gate_soft: float = ranged("[0, 1]", 0.5, "fraction of each threshold where w starts to fall (1: hard gate)")
    gate_filter_time: float = ranged("[0, 10]", 0.02, "s, time constant of the acceleration filter")
    gate_release_time: float = ranged("[0, 10]", 0.1, "s, w re-opens from 0 to 1 at most this fast")

    def __post_init__(self) -> None:
        if not self.gate_soft <= 1.0:
            key = "adaptive_rcm.gate_soft"
            raise ConfigError(f"config key '{key}' must lie in [0, 1], got {short(self.gate_soft)}", key)
        if self.gate == "speed" and self.gate_soft * self.gate_linear_speed < self.alpha * self.F_op:
            # p_R moves at up to α F_op and the scope follows it: the gate must not throttle that motion
            raise ConfigError(
                f"config key 'adaptive_rcm.gate_linear_speed' x 'gate_soft' ({self.gate_soft * self.gate_linear_speed}"
                f" m/s) must be at least alpha x F_op ({self.alpha * self.F_op} m/s), the fastest adaptation",
                "adaptive_rcm.gate_linear_speed",
            )


@dataclass(frozen=True)
class ViscousConfig:
    # below the lower bounds a 10 N push asks for > 100 m/s (or rad/s): only the limits would hold it
    k_t: float = ranged("[0.1, 10000]", 150.0, "N m s, angular damping")
    k_f: float = ranged("[0.1, 10000]", 150.0, "N s/m; the paper prints 2 (README, 'damping')")
    k_t_unguided: float = ranged("[0.1, 10000]", 2.0, "N m s, k_t while no hand grips the handle")


@dataclass(frozen=True)
class MotionConfig:
    integrator: Literal["semi_implicit", "explicit"] = "semi_implicit"
    self_motion_damping: float = ranged("[0, 1000]", 10.0, "1/s, mass-proportional damping of self-motion")
    rcm_task: Literal["lateral", "printed"] = "lateral"
    joint_limit_zone: float = ranged("[0, 1]", 0.3, "rad inside each joint limit where self-motion pushes away")
    joint_limit_stiffness: float = ranged("[0, 1000]", 5.0, "N m/rad of that push (0: off)")
    stop_time: float = ranged("[0.005, 10]", 0.1, "s, null-space brake time constant (at least 5 ticks)")


@dataclass(frozen=True)
class EnvelopeConfig:
    """Task-space envelope of the scope (issue 9), enforced by scaling lower-priority motion.

    Speeds are those of the scope about/along the RCM point; depth is the distance of the tip
    beyond the RCM point along the shaft; roll is the rotation about the shaft from the start
    pose. Each wall is approached at most at its deceleration, so the hand meets a soft wall.
    """

    enabled: bool = True
    pivot_speed_max: float = ranged("(0, 10]", 0.5, "rad/s, angular speed of the shaft about p_R")
    pivot_deceleration: float = ranged("(0, 100]", 4.0, "rad/s^2")
    insertion_speed_max: float = ranged("(0, 2]", 0.05, "m/s along the shaft")
    insertion_deceleration: float = ranged("(0, 50]", 0.5, "m/s^2")
    depth_min: float = ranged("(0, 0.6)", 0.03, "m of scope beyond p_R, shorter than scope.length")
    depth_max: float = ranged("(0, 0.6)", 0.12, "m of scope beyond p_R, shorter than scope.length")
    roll_range: float = ranged(
        "(0, 3.1]", 1.5708,
        "rad, |roll| about the shaft from the start pose; at most 3.1: the roll wraps at +-pi, and a wall at pi let"
        " its 2 mrad overshoot wrap past it (a 1 N m twist turned the scope on to 4.0 rad)",
    )
    roll_speed_max: float = ranged("(0, 10]", 1.0, "rad/s")


@dataclass(frozen=True)
class SafetyConfig:
    """Bounds the safety supervisor checks on *measured* state; each one holds the arm with an alarm."""

    max_rcm_error: float = ranged("(0, 0.1]", 0.005, "m, p_R to the scope axis at the measured joints")
    depth_tolerance: float = ranged("[0, 0.1]", 0.005, "m beyond the envelope's depth range")
    max_residual_force: float = ranged("(0, 500]", 20.0, "N, |ΔF| (eq 19): the scope's force on the wall")
    residual_force_time: float = ranged("[0, 10]", 0.05, "s |ΔF| must stay over its bound (estimate lag)")


@dataclass(frozen=True)
class InputsConfig:
    max_rcm_error: float = ranged("(0, 0.1]", 0.02, "m; larger errors are reported by the controller")
    max_image_age: float = ranged("(0, 10]", 0.2, "s; older instrument detections count as none")
    max_instruments: int = ranged("[1, 64]", 8, "more detections in one frame are a detector fault: none used")


_HEX = re.compile(r"[0-9A-Fa-f]{2}(?: ?[0-9A-Fa-f]{2}){0,7}")  # what bytes.fromhex reads, 1-8 bytes


@dataclass(frozen=True)
class TactileConfig:
    """Wire format of the tactile handle's serial frames (:class:`lapwrench.drivers.tactile.TactileFrameFormat`).

    ``header`` is hex text (``"AA55"``: bytes AA 55), 1 to 8 bytes. ``checksum`` covers the
    length byte and payload, plus the header if ``checksum_includes_header``.
    """

    header: str = "AA55"
    checksum: TactileChecksum = "none"
    length_byte: bool = False
    checksum_includes_header: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.header, str) or _HEX.fullmatch(self.header) is None:  # match's $ allows a "\n"
            raise ConfigError(
                "config key 'tactile.header' must be 1 to 8 bytes as hex text such as 'AA55', "
                f"got {short(self.header)}",
                "tactile.header",
            )


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
    tactile: TactileConfig = field(default_factory=TactileConfig)
    cues: tuple[CueEntry, ...] = DEFAULT_CUES  # the cues that run (lapwrench.config_cues)

    def cue(self, name: str) -> CueEntry | None:
        """The entry of the cue named ``name`` if it is configured and enabled, else None."""
        return next((c for c in self.cues if c.name == name and c.enabled), None)

    def replace(self, **sections: dict[str, Any]) -> Config:
        """A copy with some values changed, e.g. ``cfg.replace(tracking={"ramp": "c1"})``; validated."""
        data = to_dict(self)
        for section, values in sections.items():
            if section not in data:
                raise ConfigError(f"unknown config section {short(section)}", section)
            if not isinstance(values, dict):
                raise ConfigError(f"config section '{section}' must be a mapping, got {type(values).__name__}", section)
            data[section].update(values)
        return from_dict(data)


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
    cues = DEFAULT_CUES
    if isinstance(data, dict) and "cues" in data:  # its own parser: the cues' parameters come from plugins
        cues = parse_cues(data["cues"])
        data = {k: v for k, v in data.items() if k != "cues"}
    cfg = build(Config, data, "")
    if cues is not DEFAULT_CUES:
        cfg = dataclasses.replace(cfg, cues=cues)
    check_consistency(cfg)
    return cfg


def to_dict(cfg: Config) -> dict[str, Any]:
    """The configuration as plain YAML data (vectors as lists): what :func:`from_dict` reads back."""
    d = {k: _plain(v) for k, v in dataclasses.asdict(cfg).items()}
    d["cues"] = cues_to_dict(cfg.cues)
    return d


def _plain(x: Any) -> Any:
    """Tuples as lists, inside mappings too (what a YAML or JSON round trip gives back)."""
    if isinstance(x, dict):
        return {k: _plain(v) for k, v in x.items()}
    if isinstance(x, tuple | list):
        return [_plain(v) for v in x]
    return x


def presets() -> list[str]:
    """Names of the packaged presets (``data/presets/*.yaml``), usable wherever a config path is."""
    folder = resources.files("lapwrench").joinpath("data/presets")
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".yaml"))


def _resolve(path: str | Path) -> Path:
    """The file behind a config argument: the path itself, or the packaged preset of that name."""
    if str(path) == "":
        raise ConfigError("config file name is empty (give a YAML file or a preset: " + ", ".join(presets()) + ")")
    p = Path(path)
    try:
        exists = p.exists()
    except (OSError, ValueError):  # e.g. an embedded NUL or a name too long
        exists = False
    if not exists and str(path) in presets():
        return Path(str(resources.files("lapwrench").joinpath(f"data/presets/{path}.yaml")))
    if not exists:
        shown = config_yaml.printable(str(path))
        raise ConfigError(f"config file not found: {shown} (presets: {', '.join(presets())})")
    return p


def load(path: str | Path | None = None) -> Config:
    """Load a YAML configuration file or a packaged preset name; ``None`` gives the defaults.

    Keys missing from the file keep their defaults (the paper's parameters). Every problem is a
    :class:`ConfigError` whose message names the file (and the line, when there is one).
    """
    if path is None:
        p, source = Path(str(resources.files("lapwrench").joinpath("data/default.yaml"))), "default.yaml"
    else:
        p, source = _resolve(path), config_yaml.printable(str(path))  # quoted in every message: one line
    try:
        text = config_yaml.read_text(p, source)
    except config_yaml.YamlConfigError as exc:
        raise ConfigError(str(exc)) from exc
    try:
        data, lines = config_yaml.parse(text)
    except config_yaml.YamlConfigError as exc:
        raise ConfigError(f"{source} {exc}") from exc
    if data is None:
        data = {}
    try:
        return from_dict(data)
    except ConfigError as exc:
        line = lines.get(exc.key) if exc.key else None
        where = f"{source} line {line}" if line else source
        raise ConfigError(f"{where}: {exc}", exc.key) from exc


def dump(cfg: Config, path: str | Path) -> None:
    Path(path).write_text(yaml.safe_dump(to_dict(cfg), sort_keys=False))
