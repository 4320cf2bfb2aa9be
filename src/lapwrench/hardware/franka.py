"""A real Franka (Panda or FR3) through pylibfranka: joint position control at 1 kHz.

:class:`FrankaRobot` implements :class:`~lapwrench.robot_interface.RobotInterface` with
``Robot.start_joint_position_control`` and the ``readOnce``/``writeOnce`` pair: :meth:`read`
blocks until the robot's next 1 ms state arrives, :meth:`command` answers it with one
``JointPositions``. libfranka differentiates the commanded positions and aborts on a velocity,
acceleration or jerk discontinuity, so every command must come through the
:class:`~lapwrench.safety.supervisor.SafetySupervisor`.

External force convention
-------------------------
lapwrench's :class:`~lapwrench.sensors.RobotReading` carries ``external_force``: the total
external force acting **on** the end effector, in the base frame {B} (see
:mod:`lapwrench.rcm.adaptive`). libfranka documents ``O_F_ext_hat_K`` as the estimated external
wrench on the stiffness frame in {O} with "forces applied by the robot to the environment
positive, forces applied by the environment on the robot negative" (libfranka ``robot_state.h``;
libfranka issue #26 confirms on hardware that pulling the flange down reads a negative z). The
default ``ext_wrench_sign="robot_on_environment"`` therefore maps

    external_force = -O_F_ext_hat_K[:3].

Use ``"environment_on_robot"`` (no sign flip) if a firmware or a check on your robot says
otherwise: push the scope with a known force and compare. {O} is the robot base, taken as {B}.
The force part does not depend on where the stiffness frame K sits; the torque part is unused.

The estimate only excludes what the robot knows about: give the laparoscope assembly as the
``load`` (``Robot.set_load``) so its weight is not read as an external force.
"""

from __future__ import annotations

import contextlib
import errno
import math
import os
import socket
from dataclasses import dataclass, field
from typing import Any, Literal

import numpy as np

from lapwrench.robot.description import ARM_SPECS, RobotKind, ScopeGeometry
from lapwrench.robot.errors import RobotError
from lapwrench.sensors import RobotReading
from lapwrench.spatial import Vec

ExtWrenchSign = Literal["robot_on_environment", "environment_on_robot"]
RealtimeMode = Literal["enforce", "ignore"]

FRANKA_COMMAND_PORT = 1337  # libfranka's TCP command port (fixed; franky-sim listens there too)
PROBE_TIMEOUT_S = 3.0
_UNREACHABLE = {errno.EHOSTUNREACH, errno.ENETUNREACH, errno.EHOSTDOWN, errno.ENETDOWN, errno.EADDRNOTAVAIL}


def probe_command_port(host: str, port: int = FRANKA_COMMAND_PORT, timeout: float = PROBE_TIMEOUT_S) -> str | None:
    """Whether anything answers at ``host``: ``None`` if it does, otherwise why not (one line).

    libfranka's ``Robot(ip)`` opens a TCP connection to the command port and, when nothing answers
    (a wrong address, a cable out, the robot off), waits a minute without a word. This opens (and
    closes at once, sending nothing) the same connection with a short timeout first. A refused
    connection counts as an answer: the host is up, and libfranka itself reports it at once (FCI
    not active). Anything else (silence, an unreachable network, an unknown name) is the problem
    returned.
    """
    try:
        with socket.create_connection((host, port), timeout=timeout):
            return None
    except ConnectionRefusedError:
        return None
    except socket.gaierror as exc:
        return f"{host}: unknown host name ({exc.strerror})"
    except TimeoutError:
        return (
            f"{host}: no answer on the Franka command port {port} within {timeout:g} s "
            "(is the robot on and cabled, and the address right?)"
        )
    except OSError as exc:
        if exc.errno in _UNREACHABLE:
            return f"{host}: unreachable ({exc.strerror}); check the network cable and the address"
        return f"{host}: cannot connect to port {port} ({exc.strerror or exc})"


@dataclass(frozen=True)
class CollisionThresholds:
    """``Robot.set_collision_behavior`` thresholds: joint torques (N m) and Cartesian wrench (N, N m).

    Above a lower threshold the robot flags a contact; above an upper one it stops with a reflex.
    The defaults are high (a hand on the scope and a trocar are expected contacts), like the
    values libfranka's examples use for interaction tasks. The torque thresholds hold one value per
    joint of the Franka arm (checked against its spec by :class:`FrankaRobot`).
    """

    lower_torque: tuple[float, ...] = (20.0, 20.0, 18.0, 18.0, 16.0, 14.0, 12.0)
    upper_torque: tuple[float, ...] = (40.0, 40.0, 36.0, 36.0, 32.0, 28.0, 24.0)
    lower_force: tuple[float, ...] = (20.0, 20.0, 20.0, 25.0, 25.0, 25.0)
    upper_force: tuple[float, ...] = (40.0, 40.0, 40.0, 50.0, 50.0, 50.0)

    def __post_init__(self) -> None:
        n_torque = len(self.lower_torque)
        for name, n in (("lower_torque", n_torque), ("upper_torque", n_torque), ("lower_force", 6), ("upper_force", 6)):
            v = getattr(self, name)
            if len(v) != n or not v or not all(math.isfinite(x) and x > 0 for x in v):
                raise ValueError(f"collision.{name} must be {n} positive numbers, got {v!r}")
        if any(lo > hi for lo, hi in zip(self.lower_torque, self.upper_torque, strict=True)) or any(
            lo > hi for lo, hi in zip(self.lower_force, self.upper_force, strict=True)
        ):
            raise ValueError("collision lower thresholds must not exceed the upper ones")


@dataclass(frozen=True)
class Payload:
    """A load on the flange for ``Robot.set_load``: mass (kg), centre of mass in the flange frame (m),
    inertia about the centre of mass (kg m², 3x3 row-major = column-major since symmetric)."""

    mass: float
    com: tuple[float, float, float]
    inertia: tuple[float, ...] = field(default=(0.0,) * 9)

    @classmethod
    def from_scope(cls, scope: ScopeGeometry) -> Payload:
        """The laparoscope assembly as a load: a uniform shaft along +z, a handle cylinder and the grip
        beyond the F/T sensor (a point mass at its centre of mass).

        The mounting adapter is folded into the handle. Check against a Franka load
        identification (Desk) before relying on the force estimate.
        """
        m_s, m_h, m_g = scope.shaft_mass, scope.handle_mass, scope.grip_mass
        z_s, z_h = scope.length / 2.0, scope.handle_offset
        g = np.array(scope.grip_com, dtype=float) + np.array([0.0, 0.0, z_h])  # the grip's centre of mass in {E}
        m = m_s + m_h + m_g
        c = (m_s * np.array([0.0, 0.0, z_s]) + m_h * np.array([0.0, 0.0, z_h]) + m_g * g) / m
        i_zz = 0.5 * m_h * scope.handle_radius**2 + 0.5 * m_s * (scope.shaft_diameter / 2) ** 2
        i_xx = (
            m_s * scope.length**2 / 12.0
            + m_s * (z_s - c[2]) ** 2
            + m_h * (3 * scope.handle_radius**2 + scope.handle_length**2) / 12.0
            + m_h * (z_h - c[2]) ** 2
            + m_g * (g[2] - c[2]) ** 2
        )
        com = (float(c[0]), float(c[1]), float(c[2]))
        return cls(m, com, (i_xx, 0.0, 0.0, 0.0, i_xx, 0.0, 0.0, 0.0, i_zz))


def map_external_force(O_F_ext_hat_K: Any, sign: ExtWrenchSign) -> Vec:
    """lapwrench's ``external_force`` (on the end effector, {B}) from libfranka's ``O_F_ext_hat_K``."""
    f = np.asarray(O_F_ext_hat_K, dtype=float)[:3]
    return -f if sign == "robot_on_environment" else f.copy()


class FrankaRobot:
    """A Franka arm under joint position control through pylibfranka.

    Args:
        robot_ip: The robot's (or franky-sim's) address.
        kind: ``"panda"`` or ``"fr3"`` (selects the limit tables and the model elsewhere).
        realtime: ``"enforce"`` (real robot: needs a PREEMPT_RT kernel and realtime rights) or
            ``"ignore"`` (franky-sim, or a test bench without a realtime kernel).
        collision: Collision thresholds; ``None`` keeps the robot's current ones.
        ext_wrench_sign: How to read ``O_F_ext_hat_K`` (see the module docstring).
        report_external_force: ``False`` reports ``external_force=None`` (the controller's RCM
            adaptation then sees no residual), for robots or simulators whose estimate is absent
            (franky-sim reports zeros).
        load: Flange load for ``set_load`` (``None``: leave as configured in Desk).
        joint_impedance: Joint stiffness (N m/rad) for ``set_joint_impedance``; ``None`` keeps it.
        dt: Control period (1 ms on a Franka).

    Attributes:
        state: The latest pylibfranka ``RobotState`` (``None`` before :meth:`connect`).
        tau_J: Measured link-side joint torques (N m) of the latest state.
        robot_time: Robot time (s) since :meth:`connect`, summed from ``readOnce`` durations.
        lost_cycles: Cycles the robot reported between two reads beyond the expected one.
    """

    def __init__(
        self,
        robot_ip: str,
        *,
        kind: RobotKind = "panda",
        realtime: RealtimeMode = "enforce",
        collision: CollisionThresholds | None = None,
        ext_wrench_sign: ExtWrenchSign = "robot_on_environment",
        report_external_force: bool = True,
        load: Payload | None = None,
        joint_impedance: tuple[float, ...] | None = None,
        dt: float = 0.001,
    ) -> None:
        if kind not in ARM_SPECS or not ARM_SPECS[kind].hardware:  # the arms this driver serves
            franka = [k for k, s in ARM_SPECS.items() if s.hardware]
            raise ValueError(f"robot kind must be one of {franka} (a Franka arm), got {kind!r}")
        if realtime not in ("enforce", "ignore"):
            raise ValueError(f"realtime must be 'enforce' or 'ignore', got {realtime!r}")
        if ext_wrench_sign not in ("robot_on_environment", "environment_on_robot"):
            raise ValueError(f"unknown ext_wrench_sign {ext_wrench_sign!r}")
        self.robot_ip = robot_ip
        self.kind: RobotKind = kind
        self.realtime = realtime
        self.collision = collision if collision is not None else CollisionThresholds()
        n = ARM_SPECS[kind].n_joints
        if len(self.collision.lower_torque) != n:
            raise ValueError(f"collision torque thresholds need {n} values (one per {kind} joint), got "
                             f"{len(self.collision.lower_torque)}")
        self.ext_wrench_sign: ExtWrenchSign = ext_wrench_sign
        self.report_external_force = report_external_force
        self.load = load
        self.joint_impedance = joint_impedance
        self.dt = dt
        self.state: Any = None
        self.tau_J = np.zeros(n)
        self.robot_time = 0.0
        self.lost_cycles = 0
        self._robot: Any = None
        self._control: Any = None
        self._plf: Any = None
        self._last_q: Vec | None = None
        self._last_cmd: Vec | None = None
        self._sched: tuple[int, int] | None = None  # the connecting thread's own policy and priority

    @property
    def device(self) -> str:
        return f"Franka {self.kind} at {self.robot_ip}"

    def _import(self) -> Any:
        try:
            import pylibfranka
        except Exception as exc:  # ImportError or a missing libfranka shared library
            raise RobotError(
                f"{self.device}: pylibfranka is not usable ({exc}); pip install 'lapwrench[hardware]'"
            ) from exc
        return pylibfranka

    def _reading(self, state: Any) -> RobotReading:
        q = np.array(state.q, dtype=float)
        dq = np.array(state.dq, dtype=float)
        self.tau_J = np.array(state.tau_J, dtype=float)
        f = map_external_force(state.O_F_ext_hat_K, self.ext_wrench_sign) if self.report_external_force else None
        self._last_q = q
        return RobotReading(q, dq, f, self.robot_time)

    # -- RobotInterface -----------------------------------------------------------------------
    def connect(self) -> RobotReading:
        """Connect, configure (collision, load, impedance) and start joint position control."""
        plf = self._plf = self._import()
        rt = plf.RealtimeConfig.kEnforce if self.realtime == "enforce" else plf.RealtimeConfig.kIgnore
        self._sched = _thread_scheduling()
        try:
            self._robot = plf.Robot(self.robot_ip, rt)
        except Exception as exc:
            raise RobotError(
                f"cannot connect to the {self.device}: {type(exc).__name__}: {exc} "
                "(is it on, in FCI mode, reachable, and is the address right?)"
            ) from exc
        try:
            c = self.collision
            self._robot.set_collision_behavior(
                list(c.lower_torque), list(c.upper_torque), list(c.lower_force), list(c.upper_force)
            )
            if self.load is not None:
                self._robot.set_load(self.load.mass, list(self.load.com), list(self.load.inertia))
            if self.joint_impedance is not None:
                self._robot.set_joint_impedance(list(self.joint_impedance))
            self._control = self._robot.start_joint_position_control(plf.ControllerMode.JointImpedance)
            _not_inherited()  # libfranka raised this thread to SCHED_FIFO 99 where permitted
            state, _ = self._control.readOnce()
        except Exception as exc:
            self._release()
            raise RobotError(f"{self.device}: could not start joint position control: {exc}") from exc
        self.robot_time = 0.0
        self.lost_cycles = 0
        self.state = state
        return self._reading(state)

    def read(self) -> RobotReading:
        """Wait for the next robot state (``readOnce``) and return it."""
        if self._control is None:
            raise RobotError(f"{self.device}: not connected")
        try:
            state, duration = self._control.readOnce()
        except Exception as exc:
            raise RobotError(f"{self.device}: {type(exc).__name__}: {exc}") from exc
        d = duration.to_sec()
        self.robot_time += d
        if d > 1.5 * self.dt:
            self.lost_cycles += round(d / self.dt) - 1
        self.state = state
        return self._reading(state)

    def command(self, q_ref: Vec, *, finished: bool = False) -> None:
        """Write this cycle's joint position reference (``writeOnce``).

        ``finished=True`` marks the last command of the motion (the robot must be at rest).
        """
        if self._control is None:
            raise RobotError(f"{self.device}: not connected")
        q = [float(x) for x in q_ref]
        cmd = self._plf.JointPositions(q)
        if finished:
            cmd.motion_finished = True
        try:
            self._control.writeOnce(cmd)
        except Exception as exc:
            raise RobotError(f"{self.device}: command rejected: {type(exc).__name__}: {exc}") from exc
        self._last_cmd = np.array(q)

    def disconnect(self) -> None:
        """End the motion at the last commanded pose and release the robot.

        The caller brings the reference to rest first (``SafetySupervisor.stop``).
        """
        if self._control is not None:
            hold = self._last_cmd if self._last_cmd is not None else self._last_q
            try:
                # answer one more state with motion_finished at the held pose
                self._control.readOnce()
                if hold is not None:
                    self.command(hold, finished=True)
            except Exception:  # the connection may already be gone; release anyway
                pass
        self._release()

    def _release(self) -> None:
        robot, self._robot, self._control = self._robot, None, None
        if robot is not None:
            with contextlib.suppress(Exception):  # stop() on a dead connection
                robot.stop()
            del robot
        sched, self._sched = self._sched, None
        if sched is not None:
            _set_thread_scheduling(*sched)

    def error_recovery(self) -> None:
        """``automatic_error_recovery`` (after a reflex), outside of a control session."""
        if self._robot is None:
            raise RobotError(f"{self.device}: not connected")
        self._robot.automatic_error_recovery()


# -- the connecting thread's scheduling -------------------------------------------------------------
# libfranka's start_joint_position_control raises the calling thread to SCHED_FIFO 99 where it may (as
# root, also with RealtimeConfig.kIgnore). While connected that is the control loop's priority; but
# every process started from the thread afterwards would inherit it (a browser or a detector at
# FIFO 99 starves the machine, the loop included), and after the release the thread would keep it.
def _thread_scheduling() -> tuple[int, int]:
    """The calling thread's scheduling policy and priority (Linux: pid 0 is the calling thread)."""
    if not hasattr(os, "sched_getscheduler"):
        return (0, 0)
    return os.sched_getscheduler(0) & ~getattr(os, "SCHED_RESET_ON_FORK", 0), os.sched_getparam(0).sched_priority


def _not_inherited() -> None:
    """Keep the calling thread's real-time policy, if it has one, from passing to the processes it starts."""
    policy, priority = _thread_scheduling()
    if policy in (getattr(os, "SCHED_FIFO", -1), getattr(os, "SCHED_RR", -1)):
        _set_thread_scheduling(policy | getattr(os, "SCHED_RESET_ON_FORK", 0), priority)


def _set_thread_scheduling(policy: int, priority: int) -> None:
    with contextlib.suppress(OSError, AttributeError):
        os.sched_setscheduler(0, policy, os.sched_param(priority))
