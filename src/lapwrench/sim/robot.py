"""The MuJoCo simulation behind the robot interface: :class:`SimRobot` wraps a
:class:`~lapwrench.sim.world.SimWorld` like :class:`~lapwrench.hardware.franka.FrankaRobot` wraps a
Franka, so the hardware loop runs on either unchanged.

External force estimate
-----------------------
A Franka does not measure the force on its end effector: it estimates it from the joint torque
sensors, ``tau_ext = tau_model(q, dq, ddq) - tau_J`` mapped through the end-effector Jacobian.
:class:`SimRobot` does the same, never reading the simulator's ground truth:

1. ``tau_J`` is the simulated link-side joint torque (what the Franka's sensors measure) plus a
   configurable constant bias and Gaussian noise;
2. ``ddq`` is the finite difference of the measured joint velocities;
3. ``tau_ext = M(q) ddq + c(q, dq) + g(q) - tau_J`` with the controller's Pinocchio model (which
   includes the laparoscope, i.e. a correctly identified load), low-pass filtered;
4. the wrench on the end effector is the damped least-squares solution of ``J_E(q)^T W = tau_ext``
   and ``external_force`` its force part: the total external force *on* the end effector in {B}
   (hand + trocar), the convention of :class:`~lapwrench.sensors.RobotReading`.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from lapwrench.robot.description import RobotKind
from lapwrench.robot.interface import RobotError
from lapwrench.robot.model import RobotModel
from lapwrench.sensors import RobotReading
from lapwrench.sim.world import CONTROL_DT, SimulationUnstableError, SimWorld
from lapwrench.spatial import Vec


@dataclass(frozen=True)
class ForceEstimateConfig:
    """Torque-sensor imperfections and the estimator's filter.

    Attributes:
        torque_noise: Standard deviation (N m) of white noise on each measured joint torque.
        torque_bias: Constant offset (N m) on the measured joint torques (7 values or one).
        cutoff_hz: First-order low-pass cutoff on tau_ext (the Franka's estimate is filtered too).
        damping: Damping of the least-squares wrench solve (near singularities).
        seed: Noise generator seed.
    """

    torque_noise: float = 0.0
    torque_bias: tuple[float, ...] | float = 0.0
    cutoff_hz: float = 30.0
    damping: float = 1e-3
    seed: int = 0


class SimRobot:
    """A simulated arm with the :class:`~lapwrench.robot.interface.RobotInterface` calls.

    Args:
        world: The simulated world (its scene fixes the robot kind and the scope).
        q0: Reset the world to this configuration on :meth:`connect` (``None``: keep its state).
        estimate: External force estimator settings.
        realtime: Pace :meth:`read` to the wall clock at ``dt`` (like a robot's cycle); otherwise
            run as fast as the simulation steps.
        hand_force_H: Optional ``f(t) -> (3,)`` hand force in the handle frame {H} (N), applied to
            the world before every step (``t`` is the robot time): a scripted surgeon's hand.

    Attributes:
        tau_J: Measured joint torques (with noise and bias) of the latest reading.
        robot_time: Simulated time (s) since :meth:`connect`.
    """

    def __init__(
        self,
        world: SimWorld,
        *,
        q0: Vec | None = None,
        estimate: ForceEstimateConfig | None = None,
        realtime: bool = False,
        hand_force_H: Callable[[float], Vec] | None = None,
    ) -> None:
        self.world = world
        cfg = world.scene.config
        self.kind: RobotKind = cfg.kind
        self.dt = CONTROL_DT
        self.q0 = None if q0 is None else np.asarray(q0, dtype=float)
        self.est = estimate or ForceEstimateConfig()
        self.realtime = realtime
        self.hand_force_H = hand_force_H
        self.model = RobotModel(cfg.kind, cfg.scope)
        self._rng = np.random.default_rng(self.est.seed)
        bias = np.asarray(self.est.torque_bias, dtype=float)
        self._bias = np.broadcast_to(bias, (7,)).copy()
        self._alpha = 1.0 - np.exp(-2.0 * np.pi * self.est.cutoff_hz * self.dt)
        self.tau_J = np.zeros(7)
        self.robot_time = 0.0
        self._connected = False
        self._dq_prev: Vec | None = None
        self._tau_ext = np.zeros(7)
        self._next_wall = 0.0

    @property
    def device(self) -> str:
        return f"simulated {self.kind} (MuJoCo)"

    # -- estimation ---------------------------------------------------------------------------
    def _measure(self) -> RobotReading:
        w = self.world
        q, dq = w.q, w.dq
        tau_J = w.joint_torque_measured() + self._bias
        if self.est.torque_noise > 0:
            tau_J = tau_J + self._rng.normal(0.0, self.est.torque_noise, 7)
        self.tau_J = tau_J
        ddq = np.zeros(7) if self._dq_prev is None else (dq - self._dq_prev) / self.dt
        self._dq_prev = dq
        kin = self.model.kinematics(q, dq)
        tau_ext = kin.M @ ddq + kin.nle - tau_J
        self._tau_ext += self._alpha * (tau_ext - self._tau_ext)
        J = kin.J_E  # [angular; linear] at the {E} origin
        lam = self.est.damping
        W = np.linalg.solve(J @ J.T + lam * lam * np.eye(6), J @ self._tau_ext)
        return RobotReading(q, dq, W[3:].copy(), self.robot_time)

    # -- RobotInterface -----------------------------------------------------------------------
    def connect(self) -> RobotReading:
        """Reset the estimator (and the world to ``q0`` if given) and return the first state."""
        if self.q0 is not None:
            self.world.reset(self.q0)
        self.robot_time = 0.0
        self._dq_prev = None
        self._tau_ext = np.zeros(7)
        self._connected = True
        self._next_wall = time.perf_counter()
        r = self._measure()
        # start the filter at the static estimate instead of ramping up from zero
        q, dq = self.world.q, self.world.dq
        kin = self.model.kinematics(q, dq)
        self._tau_ext = kin.nle - self.tau_J
        return r

    def read(self) -> RobotReading:
        """The state of this cycle (paced to the wall clock when ``realtime``)."""
        if not self._connected:
            raise RobotError(f"{self.device}: not connected")
        if self.realtime:
            self._next_wall += self.dt
            delay = self._next_wall - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.05:
                self._next_wall = time.perf_counter()  # fell far behind: do not burst
        return self._measure()

    def command(self, q_ref: Vec) -> None:
        """Servo to ``q_ref`` for one 1 ms tick."""
        if not self._connected:
            raise RobotError(f"{self.device}: not connected")
        if self.hand_force_H is not None:
            _, R_H = self.world.frame_pose("lap_H")
            f = np.asarray(self.hand_force_H(self.robot_time), dtype=float)
            self.world.set_hand_wrench(np.concatenate([R_H @ f, np.zeros(3)]))
        try:
            self.world.step(np.asarray(q_ref, dtype=float))
        except SimulationUnstableError as exc:
            raise RobotError(f"{self.device}: {exc}") from exc
        self.robot_time += self.dt

    def disconnect(self) -> None:
        """Stop accepting commands (the world stays as it is)."""
        self._connected = False
