"""What the parent asks of the real-time child (:class:`RtSpec`, :class:`FtSpec`), what comes back
(:class:`RtResult`), and how it fails (:class:`RtProcessError`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from lapwrench.hardware.rt.options import RtOptions
from lapwrench.hardware.runner import LoopStats, SourceAges
from lapwrench.robot.errors import RobotError
from lapwrench.safety.supervisor import SupervisorConfig


class RtProcessError(RobotError):
    """The real-time process died, hung, or failed to start (a robot error for the CLI)."""


def _error(kind: str, message: str) -> RtProcessError:
    e = RtProcessError(message)
    e.kind = kind  # type: ignore[attr-defined]
    return e


@dataclass(frozen=True)
class FtSpec:
    """The handle F/T sensor the child opens (polled, no reader thread)."""

    kind: str  # "hex" or "ati"
    host: str
    port: int
    tare: bool = True
    tare_samples: int = 100


@dataclass
class RtSpec:
    """Everything the real-time child needs (pickled to a spawned process).

    ``robot_factory(cfg, script)`` builds the robot in the child (a module-level function or a
    ``functools.partial`` of one). ``loop_hook(loop)`` is a seam for tests and benchmarks, called on
    the built loop in the child; if it returns an object with ``report() -> dict``, that dict is
    merged into the child's final report.
    """

    cfg: Any
    robot_factory: Callable[[Any, Any], Any]
    supervisor: SupervisorConfig
    ages: SourceAges = field(default_factory=SourceAges)
    ft: FtSpec | None = None
    tactile: bool = True
    instruments: bool = False
    duration: float | None = None
    p_R: Any = None
    log_cycles: bool = True
    rt: RtOptions = field(default_factory=RtOptions)
    feeder_timeout: float = 0.5
    detector_timeout: float = 1.0
    stop_timeout: float = 5.0
    script: Any = None
    loop_hook: Callable[[Any], None] | None = None
    log_rows: int = 4096
    event_rows: int = 1024
    inputs: tuple[tuple[str, tuple[int, ...], float], ...] = ()  # registered inputs: name, shape, max age (s)

    @property
    def input_slots(self) -> tuple[tuple[str, tuple[int, ...]], ...]:
        """(name, shape) of each registered input's bus slot (:func:`~lapwrench.hardware.rt.bus.bus_layout`)."""
        return tuple((name, shape) for name, shape, _ in self.inputs)


@dataclass
class RtResult:
    """What the parent gets back: the loop's statistics and the child's report."""

    stats: LoopStats
    report: dict[str, Any]
