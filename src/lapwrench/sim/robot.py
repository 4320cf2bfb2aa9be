"""The MuJoCo simulation behind the robot interface: :class:`SimRobot` wraps a
:class:`~lapwrench.sim.world.SimWorld` like :class:`~lapwrench.hardware.franka.FrankaRobot` wraps a
Franka, so the hardware loop runs on either unchanged.

External force estimate
-----------------------
A Franka does not measure the force on its end effector: it estimates it from the joint torque
sensors. :class:`SimRobot` does the same, never reading the simulator's ground truth:

1. ``tau_J`` is the simulated link-side joint torque (what the Franka's sensors measure) plus a
   configurable constant bias and Gaussian noise. By default it is the torque's mean over the 1 ms
   tick (:meth:`~lapwrench.sim.world.SimWorld.joint_torque_tick_mean`), as a sensor sampled at
   1 kHz behind an anti-aliasing filter delivers it, not a sample of the servo's per-tick torque
   sawtooth at the end of the tick (``sampling="tick_end"``, the former model: its lateral error
   grows to tens of newtons above 1 rad/s of pivot speed, see ``bench/force_estimate.py``);
2. a generalized-momentum observer (:class:`~lapwrench.sim.sensors.ExternalForceObserver`) with
   the controller's Pinocchio model (which includes the laparoscope, i.e. a correctly identified
   load) turns it into ``tau_ext`` and, through ``J_E(q)^T``, into the wrench on the end effector;
3. ``external_force`` is its force part: the total external force *on* the end effector in {B}
   (hand + trocar), the convention of :class:`~lapwrench.sensors.RobotReading`.

Like the Franka's ``O_F_ext_hat_K`` (computed at 1 kHz from filtered joint torques) the estimate is
low-pass: the observer's first-order dynamics of bandwidth ``observer_gain`` (60 1/s, ~10 Hz).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np

from lapwrench.robot.description import RobotKind
from lapwrench.robot.errors import RobotError
from lapwrench.robot.model import RobotModel
from lapwrench.sensors import RobotReading
from lapwrench.sim.sensors import ExternalForceObserver
from lapwrench.sim.world import CONTROL_DT, SimWorld
from lapwrench.spatial import Vec


@dataclass(frozen=True)
class ForceEstimateConfig:
    """Torque-sensor imperfections and the estimator's filter.

    Attributes:
        torque_noise: Standard deviation (N m) of white noise on each measured joint torque.
        torque_bias: Constant offset (N m) on the measured joint torques (one per joint, or one for all).
        observer_gain: Bandwidth (1/s) of the momentum observer (the Franka's estimate is filtered too).
        damping: Damping of the least-squares wrench solve (near singularities).
        seed: Noise generator seed.
        sampling: ``"tick_mean"``: the joint torque averaged over each 1 ms tick (default);
            ``"tick_end"``: sampled at the end of the tick (the former model, kept for comparison).
    """

    torque_noise: float = 0.0
    torque_bias: tuple[float, ...] | float = 0.0
    observer_gain: float = 60.0
    damping: float = 1e-3
    seed: int = 0
    sampling: Literal["tick_mean", "tick_end"] = "tick_mean"

    def __post_init__(self) -> None:
        if self.sampling not in ("tick_mean", "tick_end"):
            raise ValueError(f"sampling must be 'tick_mean' or 'tick_end', got {self.sampling!r}")


NOISE_BLOCK_TICKS = 1000  # ticks of joint torque noise drawn at once


class SimRobot:
    """A simulated arm with the :class:`~lapwrench.robot_interface.RobotInterface` calls.

    Args:
        world: The simulated world (its scene fixes the robot kind and the scope).
        q0: Reset the world to this configuration on :meth:`connect` (``None``: keep its state).
        estimate: External force estimator settings.
        realtime: Pace :meth:`read` to the wall clock at ``dt`` (like a robot's cycle); otherwise
            run as fast as the simulation steps.
        hand_force_H: Optional ``f(t) -> (3,)`` hand force in the handle frame {H} (N), applied to
            the world before every step (``t`` is the robot time): a scripted surgeon's hand.
        model: The arm's :class:`RobotModel` (default: one built for the world's arm and scope).

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
        model: RobotModel | None = None,
    ) -> None:
        self.world = world
        cfg = world.scene.config
        self.kind: RobotKind = cfg.kind
        self.dt = CONTROL_DT
        self.q0 = None if q0 is None else np.asarray(q0, dtype=float)
        self.est = estimate or ForceEstimateConfig()
        self.realtime = realtime
        self.hand_force_H = hand_force_H
        # the estimator reads the model's fixed parts only (it evaluates on a workspace of its own), so
        # a caller's model of this arm and scope may serve it too
        self.model = model if model is not None else RobotModel(cfg.kind, cfg.scope)
        self._rng = np.random.default_rng(self.est.seed)
        self._noise = np.zeros((0, self.model.nv))  # torque noise drawn ahead (_torque_noise)
        self._noise_row = 0
        bias = np.asarray(self.est.torque_bias, dtype=float)
        self._bias = np.broadcast_to(bias, (self.model.nv,)).copy()
        self.observer = ExternalForceObserver(self.model, self.est.observer_gain, self.est.damping)
        self.tau_J = np.zeros(self.model.nv)
        self.robot_time = 0.0
        self._connected = False
        self._next_wall = 0.0

    @property
    def device(self) -> str:
        return f"simulated {self.kind} (MuJoCo)"

    # -- estimation ---------------------------------------------------------------------------
    def _measure(self) -> RobotReading:
        w = self.world
        q, dq = w.q, w.dq
        tau = w.joint_torque_tick_mean() if self.est.sampling == "tick_mean" else w.joint_torque_measured()
        tau_J = tau + self._bias
        if self.est.torque_noise > 0:
            tau_J += self._torque_noise()  # in place: tau_J is this reading's own array
        self.tau_J = tau_J
        force = self.observer.update(q, dq, tau_J, self.dt)
        return RobotReading(q, dq, force, self.robot_time)

    def _torque_noise(self) -> np.ndarray:
        """This tick's joint torque noise (N m): the next row of a block drawn at once, the same numbers
        as one draw of ``nv`` per tick from the same generator (a draw per tick costs microseconds)."""
        k = self._noise_row
        if k == self._noise.shape[0]:
            self._noise = self._rng.normal(0.0, self.est.torque_noise, (NOISE_BLOCK_TICKS, self.model.nv))
            k = 0
        self._noise_row = k + 1
        return self._noise[k]

    # -- RobotInterface -----------------------------------------------------------------------
    def connect(self) -> RobotReading:
        """Reset the estimator (and the world to ``q0`` if given) and return the first state."""
        if self.q0 is not None:
            self.world.reset(self.q0)
        self.robot_time = 0.0
        self.observer.reset()
        self._connected = True
        self._next_wall = time.perf_counter()
        return self._measure()

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
            self.world.set_hand_wrench(force=R_H @ f)
        self.world.step(np.asarray(q_ref, dtype=float))  # SimulationUnstableError is a RobotError
        self.robot_time += self.dt

    def disconnect(self) -> None:
        """Stop accepting commands (the world stays as it is)."""
        self._connected = False
