"""Helpers for the hardware-path tests (import as ``hardware.support``)."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lapwrench.buffer import LatestValue
from lapwrench.config import Config
from lapwrench.controller import Controller
from lapwrench.drivers.ft import Wrench
from lapwrench.drivers.tactile import TactileFrame
from lapwrench.hardware.frankysim import frankysim_available
from lapwrench.hardware.rt import CTL_CYCLES, bus_layout
from lapwrench.hardware.runner import ControlLoop, Sources
from lapwrench.hardware.shm import Bus
from lapwrench.safety.supervisor import SafetySupervisor, SupervisorConfig

FRANKYSIM_MISSING = frankysim_available()


class MemoryLogger:
    """Duck-typed RunLogger keeping every cycle and event in memory."""

    def __init__(self) -> None:
        self.cycles: list[Any] = []
        self.events: list[tuple[float, str, str]] = []

    def cycle(self, record: Any) -> None:
        self.cycles.append(record)

    def event(self, time: float, kind: str, message: str) -> None:
        self.events.append((time, kind, message))

    def kinds(self) -> set[str]:
        return {k for _, k, _ in self.events}


@dataclass
class ScriptedHand:
    """Feeds F/T and tactile latest-value buffers from a thread (a simulated handle), on wall time.

    ``force(t)`` is the hand force in {H}; ``grip(t)`` the tactile value of all 64 elements;
    ``override(t)`` may return a raw (force, torque) to publish instead (fault injection) or
    ``"silent"`` to publish nothing (a dead sensor).
    """

    force: Callable[[float], np.ndarray]
    grip: Callable[[float], int] = lambda t: 40
    override: Callable[[float], Any] | None = None
    rate_hz: float = 500.0
    ft: LatestValue[Any] = field(default_factory=lambda: LatestValue("ft"))
    tactile: LatestValue[Any] = field(default_factory=lambda: LatestValue("tactile"))

    def __post_init__(self) -> None:
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self.t0 = time.monotonic()

    def now(self) -> float:
        return time.monotonic() - self.t0

    def start(self) -> ScriptedHand:
        self.t0 = time.monotonic()
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def publish(self, t: float) -> None:
        """Publish the samples of script time ``t`` (the thread calls it on wall time; a test may
        call it from the loop's own cycle instead)."""
        o = self.override(t) if self.override is not None else None
        if o == "silent":
            return
        if o is not None:
            self.ft.put(Wrench(np.asarray(o[0], float), np.asarray(o[1], float)))
        else:
            self.ft.put(Wrench(np.asarray(self.force(t), float), np.zeros(3)))
        self.tactile.put(TactileFrame(np.full(64, self.grip(t), dtype=np.uint8)))

    def _run(self) -> None:
        while not self._stop.is_set():
            self.publish(self.now())
            self._stop.wait(1.0 / self.rate_hz)

    @property
    def sources(self) -> Sources:
        return Sources(ft=self.ft, tactile=self.tactile)


def relaxed_supervisor_config(**kw: Any) -> SupervisorConfig:
    """Supervisor for tests on this shared 2-core machine: deadline stop off unless asked.

    Deadline misses are still counted; a python controller plus (for franky-sim) a python
    simulator in another process share two cores with other jobs, so wall-clock compute time is
    not a property of the code under test here. The deadline logic has its own tests.
    """
    kw.setdefault("max_consecutive_misses", 0)
    return SupervisorConfig(**kw)


def build_loop(
    robot: Any, cfg: Config, hand: ScriptedHand | None, sup_cfg: SupervisorConfig | None = None, **kw: Any
) -> tuple[ControlLoop, MemoryLogger]:
    ctrl = Controller(cfg)
    sup = SafetySupervisor(ctrl.model.limits, cfg.robot.dt, sup_cfg or relaxed_supervisor_config())
    log = MemoryLogger()
    loop = ControlLoop(robot, ctrl, sup, hand.sources if hand else Sources(), logger=log, **kw)  # type: ignore[arg-type]
    return loop, log




# -- the process path (lapwrench.hardware.rt) -------------------------------------------
def rt_spec(cfg: Config, **kw: Any) -> Any:
    """An RtSpec on the simulated robot (paced to the wall clock), real-time settings off (tests)."""
    import functools

    from lapwrench.hardware.rt import RtOptions, RtSpec, sim_factory

    kw.setdefault("robot_factory", functools.partial(sim_factory, realtime=True))
    kw.setdefault("supervisor", relaxed_supervisor_config())
    kw.setdefault("rt", RtOptions(fifo_priority=None, lock_memory=False, warn=False))
    # heartbeat timeouts far above any stall of a loaded CI machine (a test that injects a hang
    # sets its own): the tests assert what happens, never how fast
    kw.setdefault("feeder_timeout", 5.0)
    kw.setdefault("detector_timeout", 5.0)
    return RtSpec(cfg=cfg, **kw)


def rt_process(spec: Any, **kw: Any) -> Any:
    """An RtProcess with a child heartbeat timeout for a loaded CI machine (5 s unless given)."""
    from lapwrench.hardware.rt import RtProcess

    kw.setdefault("child_timeout", 5.0)
    return RtProcess(spec, **kw)


def feeder_main(bus_name: str, bus_rows: tuple[int, int], period: float = 0.001) -> None:
    """A feeder in a process of its own (so a test can kill or stop it): beats the parent heartbeat
    and publishes a firm grip into the tactile slot, until killed."""
    from lapwrench.hardware.rt import BEAT_PARENT, bus_layout
    from lapwrench.hardware.shm import Bus

    bus = Bus.attach(bus_name, bus_layout(*bus_rows))
    beat, slot = bus["beat"], bus.slot("tactile")
    grip = np.full(64, 40.0)
    while True:
        now = time.monotonic()
        beat[BEAT_PARENT] = now
        slot.write(grip, now)
        time.sleep(period)


Pushes = tuple[tuple[float, float, tuple[float, float, float]], ...]  # (from s, until s, force N in {H})


def pushed_force(pushes: Pushes, t: float) -> np.ndarray:
    """The hand's force (N, in {H}) at time ``t`` of a schedule of constant pushes; zero between them."""
    for start, end, force in pushes:
        if start <= t < end:
            return np.array(force, dtype=float)
    return np.zeros(3)


class StallingRobot:
    """A robot whose ``read`` stalls ``stall_s`` every ``every`` cycles (a late state from the robot's side,
    as franky-sim gives on a busy machine); everything else is the wrapped robot's."""

    def __init__(self, robot: Any, every: int, stall_s: float) -> None:
        self._robot, self._every, self._stall_s, self._reads = robot, every, stall_s, 0

    def read(self) -> Any:
        self._reads += 1
        if self._reads % self._every == 0:
            time.sleep(self._stall_s)
        return self._robot.read()

    def __getattr__(self, name: str) -> Any:
        return getattr(self._robot, name)


def stalling_sim_factory(cfg: Any, script: Any, *, every: int = 250, stall_s: float = 0.03) -> Any:
    """:func:`~lapwrench.hardware.rt.sim_factory`'s robot, stalling (:class:`StallingRobot`)."""
    from lapwrench.hardware.rt import sim_factory

    return StallingRobot(sim_factory(cfg, script, realtime=True), every, stall_s)


@dataclass
class RobotTimeForce:
    """:func:`pushed_force` at the loop's robot time (its cycle count on the real-time bus times ``dt``): the
    force function of a :class:`~lapwrench.hardware.devices.SimulatedHexProcess`, so the box runs in a
    process of its own (a real box is a device of its own, never waiting for this process's interpreter)
    and its script still follows robot time. Picklable: it attaches to the bus in the box's process."""

    bus_name: str
    bus_rows: tuple[int, int]
    dt: float
    pushes: Pushes
    _bus: Any = field(default=None, repr=False)  # kept: its memory is unmapped when it goes

    def __call__(self, _wall_t: float) -> np.ndarray:
        if self._bus is None:
            self._bus = Bus.attach(self.bus_name, bus_layout(*self.bus_rows))
        return pushed_force(self.pushes, float(self._bus["ctl"][CTL_CYCLES]) * self.dt)


@dataclass
class FixedDetection:
    u: float
    v: float


class FixedDetector:
    """A detector that finds the same two instruments in every frame (and fails on an all-black one)."""

    def detect(self, image: np.ndarray) -> list[FixedDetection]:
        if image.size and int(image.max()) == 0 and getattr(self, "_warm", False):
            raise ValueError("black frame")
        self._warm = True
        return [FixedDetection(400.0, 300.0), FixedDetection(250.0, 200.0)]


def fixed_detector() -> FixedDetector:
    return FixedDetector()


def failing_detector() -> Any:
    raise RuntimeError("no such model: /nowhere/model.onnx")


class QdProbe:
    """``RtSpec.loop_hook`` for a Franka in the child: reports the robot's last ``q_d`` (the desired
    joints it reports) and whether the connect reading carried an external force."""

    def __init__(self, loop: Any) -> None:
        self.q_d: list[float] | None = None
        self.external_force_at_connect: Any = "unknown"
        robot = loop.robot
        connect, disconnect = robot.connect, robot.disconnect

        def probed_connect() -> Any:
            r = connect()
            self.external_force_at_connect = None if r.external_force is None else list(r.external_force)
            return r

        def probed_disconnect() -> None:
            if getattr(robot, "state", None) is not None:
                self.q_d = [float(x) for x in robot.state.q_d]
            disconnect()

        robot.connect, robot.disconnect = probed_connect, probed_disconnect

    def report(self) -> dict[str, Any]:
        return {"q_d_last": self.q_d, "external_force_at_connect": self.external_force_at_connect}
