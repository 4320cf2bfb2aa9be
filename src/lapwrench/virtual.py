"""Closed-loop runs of the controller on its own virtual dynamics (no physics engine).

The arm is the controller's virtual model itself: joint references are taken as the robot's
state. A scripted hand wrench acts on the handle and instruments are 3-D points projected
through the pinhole camera at the scope tip. Used by the tests and by ``lapwrench virtual``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lapwrench.config import CameraConfig, Config
from lapwrench.controller import Controller, TickResult
from lapwrench.loop import ControlLoop
from lapwrench.rcm.geometry import closest_point
from lapwrench.robot.arms import arm_spec
from lapwrench.robot.description import RobotKind
from lapwrench.robot.limits import limit_usage
from lapwrench.safety.supervisor import SafetySupervisor, SupervisorConfig
from lapwrench.sensors import ForceTorqueReading, InstrumentObservation, RobotReading, TactileReading
from lapwrench.sources import Observable, Source
from lapwrench.spatial import Mat, Vec
from lapwrench.wrenches.grip_weight import grip_weight_change

# Scope pointing straight down, arm comfortably inside its limits: the Panda's (and FR3's) home pose.
DEFAULT_Q0 = np.array(arm_spec("panda").home_pose)


def home_pose(kind: RobotKind) -> Vec:
    """The controller's default start of arm ``kind`` (its spec's ``home_pose``, rad): where virtual
    runs start unless told otherwise."""
    return np.array(arm_spec(kind).home_pose, dtype=float)


def project_points(points: Vec, p_C: Vec, R_C: Mat, cam: CameraConfig) -> tuple[Vec, np.ndarray]:
    """Pinhole projection of world points (n x 3) into the camera {C}; returns (uv, visible)."""
    pc = (np.atleast_2d(points) - p_C) @ R_C
    z = pc[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = cam.u0 + cam.fx * pc[:, 0] / z
        v = cam.v0 + cam.fy * pc[:, 1] / z
    visible = (z > 1e-3) & (u >= 0) & (u <= cam.width) & (v >= 0) & (v <= cam.height)
    return np.stack([u, v], axis=1), visible


def tactile_for_delta(delta: float, k_H: float, elements: int = 32) -> Vec:
    """A grip pattern whose eq (7) gain is ``delta``: ``elements`` equal non-zero values."""
    values = np.zeros(64)
    if delta > 0:
        values[:elements] = min(255.0, delta * k_H / elements)
    return values


@dataclass
class HandScript:
    """Hand force (in {H}) and grip gain as functions of time."""

    force: Callable[[float], Vec] = lambda t: np.zeros(3)
    torque: Callable[[float], Vec] = lambda t: np.zeros(3)
    delta: Callable[[float], float] = lambda t: 0.0


@dataclass
class VirtualLog:
    t: list[float] = field(default_factory=list)
    results: list[TickResult] = field(default_factory=list)
    pixels: list[Vec] = field(default_factory=list)
    axis_points: list[tuple[Vec, Vec]] = field(default_factory=list)
    alarm: str | None = None  # the supervisor's alarm that ended the run early, if any

    def array(self, name: str) -> np.ndarray:
        return np.array([getattr(r, name) for r in self.results])


class VirtualRobot:
    """The controller's virtual model as the robot: it is exactly where it was commanded.

    A :class:`~lapwrench.robot_interface.RobotInterface`: ``read`` returns the last command as the
    measured position, its difference over one period as the velocity, and no force estimate.
    """

    def __init__(self, kind: RobotKind, q0: Vec, dt: float) -> None:
        self.kind: RobotKind = kind
        self.dt = dt
        self.q = np.array(q0, dtype=float)
        self.dq = np.zeros_like(self.q)
        self.t = 0.0

    def connect(self) -> RobotReading:
        return RobotReading(self.q.copy(), self.dq.copy(), None, self.t)

    def read(self) -> RobotReading:
        return RobotReading(self.q.copy(), self.dq.copy(), None, self.t)

    def command(self, q_ref: Vec) -> None:
        q = np.asarray(q_ref, dtype=float)
        self.dq = (q - self.q) / self.dt
        self.q = q.copy()
        self.t += self.dt

    def disconnect(self) -> None:
        """Nothing to release."""


def run_virtual(
    cfg: Config,
    duration: float,
    hand: HandScript | None = None,
    instruments: Callable[[float], Vec] | None = None,
    q0: Vec | None = None,
    p_R: Vec | None = None,
    controller: Controller | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[Controller, VirtualLog]:
    """Run the controller for ``duration`` seconds through the one control loop
    (:class:`lapwrench.loop.ControlLoop`) on its own virtual model (:class:`VirtualRobot`), with the
    safety supervisor in the path. A supervisor alarm ends the run (the arm stopped to rest first);
    ``VirtualLog.alarm`` says why. ``q0`` defaults to the configured arm's :func:`home_pose`.
    """
    ctrl = controller or Controller(cfg)
    hand = hand or HandScript()
    log = VirtualLog()
    dt = cfg.robot.dt
    robot = VirtualRobot(cfg.robot.kind, home_pose(cfg.robot.kind) if q0 is None else q0, dt)
    clock = [0.0]
    pixels = [np.zeros((0, 2))]

    def observe(t: float) -> InstrumentObservation | None:
        if instruments is None:
            return None
        kin = ctrl.model.kinematics(robot.q, robot.dq)
        uv, vis = project_points(instruments(t), kin.p_C, kin.R_C, cfg.camera)
        pixels[0] = uv[vis]
        return InstrumentObservation(pixels[0], t)

    grip_mass, grip_com = float(cfg.scope.grip_mass), np.array(cfg.scope.grip_com, dtype=float)
    # {H} is parallel to {E}: its rotation is {E}'s placement (one forward kinematics pass, a view to copy)
    R_H0 = ctrl.model.placement_E_into(robot.q)[0].copy()  # where the sensor is tared, the handle untouched

    def read_ft(t: float) -> ForceTorqueReading:
        """The hand's wrench plus what the grip's weight adds since the tare, as a real sensor reads it."""
        force, torque = hand.force(t), hand.torque(t)
        if grip_mass > 0.0:
            dF, dT = grip_weight_change(ctrl.model.placement_E_into(robot.q)[0], R_H0, grip_mass, grip_com)
            force, torque = force + dF, torque + dT
        return ForceTorqueReading(force, torque, t)

    sources: list[Source] = [
        Observable("ft", read_ft, update_interval=dt, max_age=dt),
        Observable("tactile", lambda t: TactileReading(tactile_for_delta(hand.delta(t), cfg.interaction.k_H), t),
                   update_interval=dt, max_age=dt),
    ]
    if instruments is not None:
        sources.append(Observable("instruments", observe, update_interval=dt, max_age=dt))
    sup = SafetySupervisor(ctrl.model.limits, dt, SupervisorConfig.from_config(cfg, max_consecutive_misses=0))
    loop = ControlLoop(robot, ctrl, sup, sources, clock=lambda: clock[0], wall_deadlines=False, switch_interval=None)
    loop.start(p_R)
    steps = round(duration / dt)
    for k in range(steps):
        c = loop.cycle()
        clock[0] += dt
        if c.result is None or sup.alarm:
            log.alarm = sup.alarm_reason
            while not sup.at_rest and loop.k < 10 * steps + 10_000:
                loop.hold_cycle()
            break
        kin = ctrl.model.kinematics(robot.q, robot.dq)
        log.t.append(c.frame.time)
        log.results.append(c.result)
        log.pixels.append(pixels[0])
        tip, _ = closest_point(kin, 1.0, cfg.scope.length)  # eq (31) at s* = 1: the scope tip
        log.axis_points.append((kin.p_E.copy(), tip))
        if progress is not None:
            progress(k, steps)
    return ctrl, log


def limits_report(ctrl: Controller, log: VirtualLog, q0: Vec) -> dict[str, float]:
    q = np.array([r.q_ref for r in log.results])
    return limit_usage(q, ctrl.dt, ctrl.model.limits, q0)


def plot_virtual(log: VirtualLog, cfg: Config, path: Path, title: str = "virtual closed loop") -> None:
    """RCM error, wrenches, grip gain, pixel distance and mode over time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.array(log.t)
    e = np.array([r.rcm_error for r in log.results]) * 1e3
    off = np.zeros(6)  # a cue the configuration switched off has no wrench: drawn as zero
    Fh = np.array([np.linalg.norm(r.wrenches.get("interaction", off)[3:]) for r in log.results])
    Fc = np.array([np.linalg.norm(r.wrenches.get("tracking", off)[3:]) for r in log.results])
    delta = np.array([r.delta for r in log.results])
    d = np.array(
        [
            np.min(np.hypot(p[:, 0] - cfg.camera.u0, p[:, 1] - cfg.camera.v0)) if len(p) else np.nan
            for p in log.pixels
        ]
    )
    modes = ["idle", "tracking", "handle", "handle+tracking", "handle-dominant"]
    m = np.array([modes.index(r.mode) for r in log.results])
    fig, ax = plt.subplots(5, 1, figsize=(9, 11), sharex=True)
    ax[0].plot(t, e)
    ax[0].set_ylabel("RCM error |e_R| (mm)")
    ax[1].plot(t, Fh, label="|F_h| (handle)")
    ax[1].plot(t, Fc, label="|F_c| (tracking)")
    ax[1].set_ylabel("force (N)")
    ax[1].legend(loc="upper right")
    ax[2].plot(t, delta)
    ax[2].set_ylabel("grip gain δ")
    ax[3].plot(t, d)
    ax[3].axhline(cfg.tracking.epsilon1, ls="--", c="g", label="ε1")
    ax[3].axhline(cfg.tracking.epsilon2, ls="--", c="r", label="ε2")
    ax[3].set_ylabel("instrument distance (px)")
    ax[3].legend(loc="upper right")
    ax[4].step(t, m, where="post")
    ax[4].set_yticks(range(len(modes)), modes)
    ax[4].set_xlabel("time (s)")
    fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
