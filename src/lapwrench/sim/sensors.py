"""Simulated sensors, each with configurable noise, bias and rate.

- :class:`SimForceTorqueSensor`: the 6-axis F/T between handle grip and scope. It reads MuJoCo's
  force/torque sensors at ``lap_H`` (the interaction the physics transmits through the sensor
  body), so it sees the hand's wrench and nothing else.
- :class:`TactileGripModel`: the 64-element grip array. A grip force becomes a contact patch whose
  size grows with the force, and element values 0-255 (the inputs of eq 7).
- :class:`ExternalForceObserver`: the robot's estimate of the external force on the end effector
  from the *measured* joint torques (used by :class:`lapwrench.sim.robot.SimRobot`, which adds the
  torque sensors' noise and bias). It includes the trocar force.
- :class:`SimCamera`: laparoscope frames rendered at 25 fps.

Every model draws from its own seeded generator, so a run is reproducible from its seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from lapwrench.robot.model import RobotModel
from lapwrench.sensors import ForceTorqueReading, TactileReading
from lapwrench.sim.scene import FT_FORCE_SENSOR, FT_TORQUE_SENSOR
from lapwrench.sim.world import SimWorld


def _check_rate(rate_hz: float, name: str) -> None:
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"{name}.rate_hz must be positive, got {rate_hz!r}")


class _SampleAndHold:
    """Emits a new sample every 1/rate seconds and holds it in between."""

    def __init__(self, rate_hz: float) -> None:
        self.period = 1.0 / rate_hz
        self.next_time = 0.0

    def due(self, t: float) -> bool:
        if t + 1e-9 >= self.next_time:
            self.next_time = max(self.next_time + self.period, t)
            return True
        return False


@dataclass(frozen=True)
class ForceTorqueNoise:
    """HEX-E class figures: ~0.1 N / 0.005 N m noise, a few tenths of a newton of bias."""

    rate_hz: float = 500.0
    force_sigma: float = 0.1
    torque_sigma: float = 0.005
    force_bias: tuple[float, float, float] = (0.2, -0.1, 0.3)
    torque_bias: tuple[float, float, float] = (0.005, 0.0, -0.004)


class SimForceTorqueSensor:
    """Handle F/T: the wrench the hand applies to the scope, in {H}, plus noise and bias."""

    def __init__(self, world: SimWorld, noise: ForceTorqueNoise | None = None, seed: int = 0) -> None:
        self.world = world
        self.noise = noise or ForceTorqueNoise()
        _check_rate(self.noise.rate_hz, "ft")
        m = world.model
        self._f = m.sensor(FT_FORCE_SENSOR).adr[0]
        self._m = m.sensor(FT_TORQUE_SENSOR).adr[0]
        self._rng = np.random.default_rng(seed)
        self._clock = _SampleAndHold(self.noise.rate_hz)
        self._last: ForceTorqueReading | None = None
        self._bias_est = np.zeros(6)

    def _raw(self) -> np.ndarray:
        d = self.world.data.sensordata
        # MuJoCo reports the force the scope exerts on the grip body; the hand's is its opposite.
        wrench = -np.concatenate([d[self._f : self._f + 3], d[self._m : self._m + 3]])
        n = self.noise
        wrench[:3] += np.asarray(n.force_bias) + n.force_sigma * self._rng.standard_normal(3)
        wrench[3:] += np.asarray(n.torque_bias) + n.torque_sigma * self._rng.standard_normal(3)
        return wrench

    def tare(self, samples: int = 200) -> None:
        """Average ``samples`` readings with the hand off and subtract them (as done with a real F/T)."""
        self._bias_est = np.mean([self._raw() for _ in range(samples)], axis=0)

    def read(self, t: float) -> ForceTorqueReading:
        if self._last is None or self._clock.due(t):
            w = self._raw() - self._bias_est
            self._last = ForceTorqueReading(w[:3], w[3:], t)
        return self._last


@dataclass(frozen=True)
class GripModel:
    """Tactile response of the handle to a grip force (N).

    The contact patch covers ``min(64, a * F**0.5)`` elements and each contacted element reads
    ``b * F / n_c`` (pressure) plus noise, clipped to 0-255 and rounded like the real array.
    With the defaults a 30 N grip gives δ ≈ 2.0, 17 N ≈ 1.1 and 5 N ≈ 0.3 (k_H = 2000).
    """

    rate_hz: float = 100.0
    patch_per_sqrt_newton: float = 8.5
    counts_per_newton: float = 133.0
    element_sigma: float = 3.0


class TactileGripModel:
    """The 64-element grip array driven by a grip force."""

    def __init__(self, model: GripModel | None = None, seed: int = 0) -> None:
        self.model = model or GripModel()
        _check_rate(self.model.rate_hz, "tactile")
        self._rng = np.random.default_rng(seed)
        self._clock = _SampleAndHold(self.model.rate_hz)
        self._order = self._rng.permutation(64)  # which elements the palm covers first
        self._last: TactileReading | None = None

    def values(self, grip_force: float) -> np.ndarray:
        m = self.model
        out = np.zeros(64)
        if grip_force <= 0.0:
            return out
        n_c = int(min(64, round(m.patch_per_sqrt_newton * np.sqrt(grip_force))))
        if n_c == 0:
            return out
        per = m.counts_per_newton * grip_force / n_c
        vals = per + m.element_sigma * self._rng.standard_normal(n_c)
        out[self._order[:n_c]] = np.clip(np.round(vals), 1.0, 255.0)
        return out

    def read(self, t: float, grip_force: float) -> TactileReading:
        if self._last is None or self._clock.due(t):
            self._last = TactileReading(self.values(grip_force), t)
        return self._last


class ExternalForceObserver:
    """Estimated external force on the end effector in {B} from measured joint torques.

    Generalized-momentum observer (De Luca et al.), as robots with joint torque sensors use: with
    p = M(q) q̇,

        r(t) = K_O [ p(t) - p(0) - ∫ (τ_J + C(q, q̇)ᵀ q̇ - g(q) + r) dt ],

    r → τ_ext with first-order dynamics of bandwidth K_O (1/s), without differentiating q̇. The
    external wrench at {E} is the damped least-squares solution of τ_ext = J_Eᵀ W; its force part
    is the total external force, hand plus trocar.
    """

    def __init__(self, model: RobotModel, gain: float = 60.0, damping: float = 1e-3) -> None:
        if not (np.isfinite(gain) and gain > 0):
            raise ValueError(f"observer gain must be positive, got {gain!r}")
        self.model = model
        self.gain = gain
        self.damping = damping
        self.r = np.zeros(7)
        self._integral = np.zeros(7)
        self._p0: np.ndarray | None = None
        self._data = model.model.createData()
        self._lower = np.tril_indices(7, -1)

    def reset(self) -> None:
        self.r = np.zeros(7)
        self._integral = np.zeros(7)
        self._p0 = None

    def update(self, q: np.ndarray, dq: np.ndarray, tau_J: np.ndarray, dt: float) -> np.ndarray:
        """Advance one tick with the measured joint torques; returns the external force (N, {B})."""
        m, d = self.model.model, self._data
        M = pin.crba(m, d, q).copy()
        M[self._lower] = M.T[self._lower]
        p = M @ dq
        C = pin.computeCoriolisMatrix(m, d, q, dq)
        g = pin.computeGeneralizedGravity(m, d, q)
        if self._p0 is None:
            self._p0 = p.copy()
        self._integral += (tau_J + C.T @ dq - g + self.r) * dt
        self.r = self.gain * (p - self._p0 - self._integral)
        pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacements(m, d)
        J = pin.getFrameJacobian(m, d, self.model.frame_E, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        lam2 = self.damping**2
        wrench = np.linalg.solve(J @ J.T + lam2 * np.eye(6), J @ self.r)  # [force; torque] in Pinocchio order
        return wrench[:3]


class SimCamera:
    """Laparoscope frames at ``fps`` (default 25), rendered headless without shadows."""

    def __init__(self, world: SimWorld, fps: float = 25.0) -> None:
        _check_rate(fps, "camera")
        self.fps = fps
        self.world = world
        self._clock = _SampleAndHold(fps)
        self.frame: np.ndarray | None = None
        self.stamp = -np.inf

    def capture(self, t: float) -> bool:
        """Render a new frame if one is due at ``t``; returns True when it did."""
        if self._clock.due(t):
            self.frame = self.world.render()
            self.stamp = t
            return True
        return False
