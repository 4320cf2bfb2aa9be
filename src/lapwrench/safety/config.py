"""The safety supervisor's thresholds, states and events (:mod:`lapwrench.safety.supervisor`).

:class:`SupervisorConfig` holds every threshold the supervisor checks; its measured-state bounds
come from the YAML ``safety`` and ``envelope`` sections (:meth:`SupervisorConfig.from_config`), so
every loop reads them the same way. :class:`SupervisorState` is where the supervisor is in a run
(passing commands, braking, holding) and :class:`SupervisorEvent` one structured event it logs.
Kept apart from the supervisor so the types every loop and logger imports stay small.
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, fields
from enum import StrEnum
from typing import Any

from lapwrench.config import Config, EnvelopeConfig, SafetyConfig


def _measured_bounds(safety: SafetyConfig, envelope: EnvelopeConfig) -> dict[str, float]:
    """The supervisor's measured-state bounds from the config sections (m, m, m, N)."""
    return {
        "max_rcm_error": safety.max_rcm_error,
        "depth_min": envelope.depth_min - safety.depth_tolerance,
        "depth_max": envelope.depth_max + safety.depth_tolerance,
        "max_residual_force": safety.max_residual_force,
        "residual_force_time": safety.residual_force_time,
    }


_DEFAULT_BOUNDS = _measured_bounds(SafetyConfig(), EnvelopeConfig())  # those of data/default.yaml


class SupervisorState(StrEnum):
    """``running``: commands pass; ``stopping``: braking to rest; ``holding``: at rest, holding."""

    RUNNING = "running"
    STOPPING = "stopping"
    HOLDING = "holding"


@dataclass(frozen=True)
class SupervisorEvent:
    """One supervisor event. ``time`` is the loop's session time (s)."""

    time: float
    kind: str
    message: str


@dataclass(frozen=True)
class SupervisorConfig:
    """Supervisor thresholds.

    The measured-state bounds default to the shipped ``safety`` and ``envelope`` sections; build a
    loop's configuration with :meth:`from_config` so every loop reads them from the YAML the same way.

    Attributes:
        check_fraction: Fraction of the Franka velocity/acceleration/jerk limits a command may use
            (1.0: the hard limits; the controller's shaper uses ``robot.limit_fraction`` < 1).
        stop_fraction: Fraction of the limits used by the stop trajectory.
        position_tolerance: Slack (rad) on the position-limit check of commands.
        max_rcm_error: Measured RCM error (m) above which the robot holds with an alarm.
        depth_min: Measured insertion depth (m) below which the robot holds with an alarm.
        depth_max: Measured insertion depth (m) above which the robot holds with an alarm.
        max_residual_force: Residual |ΔF| (N, eq 19) above which the robot holds with an alarm ...
        residual_force_time: ... once it has stayed above for this long (s): the robot's force
            estimate lags the handle sensor, so a hand letting go of 30 N at once shows |ΔF| of
            ~26 N for about 25 ms without any load on the wall. A non-finite |ΔF| holds at once.
        max_joint_step: Largest move (rad) of a measured joint from one reading to the next; more stops
            with an alarm. No arm moves 20 mrad in a millisecond (20 rad/s, eight times the Franka's
            fastest joint, and still 4 rad/s over a 5 ms gap in the readings): such a step is a corrupt
            reading, which the RCM and depth watches do not see when the scope's axis stays put (a glitch
            of the last joint turns the scope about its own axis).
        joint_warn_margin: Measured distance (rad) to a joint limit that logs an event.
        joint_stop_margin: Measured distance (rad) to a joint limit that stops with an alarm.
        cycle_budget: Compute time (s) allowed per cycle; more is a deadline miss.
        max_consecutive_misses: Deadline misses in a row that stop with an alarm (0: never).
        rest_velocity: Velocity (rad/s) under which, with the acceleration ramped out, a stopping
            reference counts as at rest.
        max_events: Events kept in memory.
    """

    check_fraction: float = 1.0
    stop_fraction: float = 0.9
    position_tolerance: float = 1e-6
    max_rcm_error: float = _DEFAULT_BOUNDS["max_rcm_error"]
    depth_min: float = _DEFAULT_BOUNDS["depth_min"]
    depth_max: float = _DEFAULT_BOUNDS["depth_max"]
    max_residual_force: float = _DEFAULT_BOUNDS["max_residual_force"]
    residual_force_time: float = _DEFAULT_BOUNDS["residual_force_time"]
    max_joint_step: float = 0.02
    joint_warn_margin: float = 0.04
    joint_stop_margin: float = 0.01
    cycle_budget: float = 0.0008
    max_consecutive_misses: int = 20
    rest_velocity: float = 1e-4
    max_events: int = 10_000

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, numbers.Real):
                raise ValueError(f"supervisor.{f.name} must be a number, got {v!r}")
        for name in (
            "check_fraction", "stop_fraction", "max_rcm_error", "max_residual_force", "max_joint_step", "cycle_budget",
            "rest_velocity",
        ):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"supervisor.{name} must be positive, got {v!r}")
        for name in ("position_tolerance", "residual_force_time"):  # NaN or inf would switch a check off
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"supervisor.{name} must be finite and >= 0, got {v!r}")
        if self.check_fraction > 1.0 or self.stop_fraction > 1.0:
            raise ValueError("supervisor check_fraction and stop_fraction must be <= 1")
        if not (math.isfinite(self.depth_min) and math.isfinite(self.depth_max) and self.depth_min < self.depth_max):
            raise ValueError(f"need finite depth_min < depth_max, got {self.depth_min!r}, {self.depth_max!r}")
        if not 0 <= self.joint_stop_margin <= self.joint_warn_margin:
            raise ValueError("need 0 <= joint_stop_margin <= joint_warn_margin")
        for name in ("max_consecutive_misses", "max_events"):
            v = getattr(self, name)
            if not isinstance(v, numbers.Integral) or v < 0:
                raise ValueError(f"supervisor.{name} must be a whole number >= 0, got {v!r}")

    @classmethod
    def from_config(cls, cfg: Config, **overrides: Any) -> SupervisorConfig:
        """The measured-state bounds of ``cfg.safety`` and ``cfg.envelope``; ``overrides`` set the
        other thresholds (or replace a bound)."""
        return cls(**{**_measured_bounds(cfg.safety, cfg.envelope), **overrides})
