"""Simulated sensors, each with configurable noise, bias and rate.

- :class:`SimForceTorqueSensor`: the 6-axis F/T between handle grip and scope. It reads MuJoCo's
  force/torque sensors at ``lap_H`` (the interaction the physics transmits through the sensor
  body), so it sees the hand's wrench and nothing else.
- :class:`TactileGripModel`: the 64-element grip array. A grip force becomes a contact patch whose
  size grows with the force, and element values 0-255 (the inputs of eq 7).
- :class:`ExternalForceObserver`: the robot's estimate of the external force on the end effector
  from the *measured* joint torques (used by :class:`lapwrench.sim.robot.SimRobot`, which adds the
  torque sensors' noise and bias). It includes the trocar force.
- the camera: :class:`~lapwrench.sim.camera.SimCamera`, in :mod:`lapwrench.sim.camera`.

Every model draws from its own seeded generator, so a run is reproducible from its seed.

The observer's per-tick algebra is one numba kernel (:func:`_observer_step`) around the Pinocchio
calls; the F/T sensor reads its six sensor values through cached addresses.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from lapwrench.inputs import as_f64_c
from lapwrench.jit import bind, kernel
from lapwrench.robot.model import RobotModel
from lapwrench.sensors import ForceTorqueReading, TactileReading
from lapwrench.sim.scene.names import FT_FORCE_SENSOR, FT_TORQUE_SENSOR
from lapwrench.sim.world import SimWorld
from lapwrench.spatial import lu_solve


def check_rate(rate_hz: float, name: str) -> None:
    """ValueError unless ``rate_hz`` (a sensor's ``name``) is a positive number."""
    if not (np.isfinite(rate_hz) and rate_hz > 0):
        raise ValueError(f"{name}.rate_hz must be positive, got {rate_hz!r}")


class SampleAndHold:
    """Emits a new sample every 1/rate seconds and holds it in between."""

    def __init__(self, rate_hz: float) -> None:
        self.period = 1.0 / rate_hz
        self.next_time = 0.0

    def due(self, t: float) -> bool:
        if t + 1e-9 >= self.next_time:
            self.next_time = max(self.next_time + self.period, t)
            return True
        return False


_ZERO6 = np.zeros(6)
NOISE_BLOCK_SAMPLES = 500  # F/T samples of noise drawn at once (a draw per sample costs microseconds)


@kernel
def _ft_sample(
    sensordata: np.ndarray,
    adr: np.ndarray,
    bias: np.ndarray,
    sigma: np.ndarray,
    z: np.ndarray,
    tare: np.ndarray,
    out: np.ndarray,
) -> None:
    """out = (-sensordata[adr] + (bias + sigma z)) - tare, element by element (numpy's order).

    MuJoCo reports the force the scope exerts on the grip body; the hand's is its opposite.
    """
    for i in range(adr.size):
        out[i] = (-sensordata[adr[i]] + (bias[i] + sigma[i] * z[i])) - tare[i]


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
        check_rate(self.noise.rate_hz, "ft")
        m = world.model
        self._f = m.sensor(FT_FORCE_SENSOR).adr[0]
        self._m = m.sensor(FT_TORQUE_SENSOR).adr[0]
        self._adr = np.r_[self._f : self._f + 3, self._m : self._m + 3]  # [force; torque] in sensordata
        self._sensordata = world.data.sensordata  # a view: MjData's arrays never move
        self._noise_of: ForceTorqueNoise | None = None  # the noise settings _bias6, _sigma6 are of
        z6 = np.zeros(6)
        self._ft_sample = bind(_ft_sample, self._sensordata, self._adr, z6, z6, z6, z6, z6)
        self._rng = np.random.default_rng(seed)
        self._z = np.zeros((0, 6))  # standard normal draws taken ahead, a row per sample (_next_z)
        self._z_row = 0
        self._clock = SampleAndHold(self.noise.rate_hz)
        self._last: ForceTorqueReading | None = None
        self._bias_est = np.zeros(6)

    def _sample(self, tare: np.ndarray) -> np.ndarray:
        """The sensor's wrench with its noise and bias, minus ``tare``."""
        n = self.noise
        if n is not self._noise_of:
            self._bias6 = np.concatenate([np.asarray(n.force_bias, float), np.asarray(n.torque_bias, float)])
            self._sigma6 = np.array([n.force_sigma] * 3 + [n.torque_sigma] * 3, float)
            self._noise_of = n
        w = np.empty(6)
        self._ft_sample(self._sensordata, self._adr, self._bias6, self._sigma6, self._next_z(), tare, w)
        return w

    def _next_z(self) -> np.ndarray:
        """This sample's six standard normal draws: force noise then torque noise, three each. The next
        row of a block drawn at once: the same numbers as six draws per sample from the same generator."""
        k = self._z_row
        if k == self._z.shape[0]:
            self._z = self._rng.standard_normal((NOISE_BLOCK_SAMPLES, 6))
            k = 0
        self._z_row = k + 1
        return self._z[k]

    def _raw(self) -> np.ndarray:
        return self._sample(_ZERO6)  # x - 0.0 == x: the untared wrench, bit for bit

    def tare(self, samples: int = 200) -> None:
        """Average ``samples`` readings with the hand off and subtract them (as done with a real F/T)."""
        self._bias_est = np.mean([self._raw() for _ in range(samples)], axis=0)

    def read(self, t: float) -> ForceTorqueReading:
        if self._last is None or self._clock.due(t):
            w = self._sample(np.ascontiguousarray(self._bias_est, dtype=float))
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
        check_rate(self.model.rate_hz, "tactile")
        self._rng = np.random.default_rng(seed)
        self._clock = SampleAndHold(self.model.rate_hz)
        self._order = self._rng.permutation(64)  # which elements the palm covers first
        self._last: TactileReading | None = None

    def values(self, grip_force: float) -> np.ndarray:
        m = self.model
        out = np.zeros(64)
        if grip_force <= 0.0:
            return out
        n_c = int(min(64, round(m.patch_per_sqrt_newton * math.sqrt(grip_force))))
        if n_c == 0:
            return out
        per = m.counts_per_newton * grip_force / n_c
        vals = np.round(per + m.element_sigma * self._rng.standard_normal(n_c))
        np.maximum(vals, 1.0, out=vals)  # clip to 1-255 (np.clip, without its overhead)
        np.minimum(vals, 255.0, out=vals)
        out[self._order[:n_c]] = vals
        return out

    def read(self, t: float, grip_force: float) -> TactileReading:
        if self._last is None or self._clock.due(t):
            self._last = TactileReading(self.values(grip_force), t)
        return self._last


@kernel
def _observer_step(
    M: np.ndarray,
    C: np.ndarray,
    g: np.ndarray,
    J: np.ndarray,
    dq: np.ndarray,
    tau_J: np.ndarray,
    r: np.ndarray,
    dt: float,
    gain: float,
    lam2: float,
    first: bool,
    p0: np.ndarray,
    integral: np.ndarray,
    r_new: np.ndarray,
    force: np.ndarray,
) -> bool:
    """One observer tick (see :class:`ExternalForceObserver`); False if the wrench solve is singular.

    ``M``: Pinocchio's CRBA output (its upper triangle is used), ``C``: Coriolis matrix, ``g``:
    gravity torque, ``J``: 6 x n frame Jacobian of {E} in {B} axes ([linear; angular] rows), ``r``:
    the previous residual. Writes the new residual into ``r_new`` and the force part of the damped
    least-squares wrench, (J Jᵀ + λ² I)⁻¹ J r, into ``force``; sets ``p0`` on the ``first`` tick.
    """
    n = dq.size
    p = np.empty(n)
    for i in range(n):  # p = M q̇ (M symmetric, from its upper triangle)
        s = 0.0
        for j in range(n):
            s += (M[i, j] if j >= i else M[j, i]) * dq[j]
        p[i] = s
    if first:
        p0[:] = p
    for i in range(n):
        ctq = 0.0  # (Cᵀ q̇)_i
        for j in range(n):
            ctq += C[j, i] * dq[j]
        integral[i] += (tau_J[i] + ctq - g[i] + r[i]) * dt
        r_new[i] = gain * (p[i] - p0[i] - integral[i])
    m = J.shape[0]
    A = np.empty((m, m))
    b = np.empty(m)
    for i in range(m):
        for k in range(m):
            s = 0.0
            for j in range(n):
                s += J[i, j] * J[k, j]
            A[i, k] = s + lam2 if i == k else s
        s = 0.0
        for j in range(n):
            s += J[i, j] * r_new[j]
        b[i] = s
    x, ok = lu_solve(A, b)  # partial pivoting, LAPACK gesv's method
    if not ok:
        return False
    for i in range(force.size):
        force[i] = x[i]
    return True




class ExternalForceObserver:
    """Estimated external force on the end effector in {B} from measured joint torques.

    Generalized-momentum observer (De Luca et al.), as robots with joint torque sensors use: with
    p = M(q) q̇,

        r(t) = K_O [ p(t) - p(0) - ∫ (τ_J + C(q, q̇)ᵀ q̇ - g(q) + r) dt ],

    r → τ_ext with first-order dynamics of bandwidth K_O (1/s), without differentiating q̇. The
    external wrench at {E} is the damped least-squares solution of τ_ext = J_Eᵀ W; its force part
    is the total external force, hand plus trocar.

    Pinocchio computes M, C, g and J_E; the algebra of a tick is the compiled
    :func:`_observer_step` (:meth:`update_reference` is the same tick in plain numpy).
    """

    def __init__(self, model: RobotModel, gain: float = 60.0, damping: float = 1e-3) -> None:
        if not (np.isfinite(gain) and gain > 0):
            raise ValueError(f"observer gain must be positive, got {gain!r}")
        self.model = model
        self.gain = gain
        self.damping = damping
        n = model.nv
        self.r = np.zeros(n)
        self._integral = np.zeros(n)
        self._p0: np.ndarray | None = None
        self._data = model.model.createData()
        self._lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        self._lower = np.tril_indices(n, -1)
        self._step: Callable[..., bool] | None = None  # _observer_step bound to its argument types at the first update
        # Compile the tick (or load it from numba's cache) now, not in the first reading.
        self.update(pin.neutral(model.model), np.zeros(n), np.zeros(n), 1e-3)
        self.reset()

    def reset(self) -> None:
        self.r = np.zeros(self.model.nv)
        self._integral = np.zeros(self.model.nv)
        self._p0 = None

    def update(self, q: np.ndarray, dq: np.ndarray, tau_J: np.ndarray, dt: float) -> np.ndarray:
        """Advance one tick with the measured joint torques; returns the external force (N, {B})."""
        m, d = self.model.model, self._data
        # The bound kernel takes C-contiguous float64 vectors of the model's size, exactly.
        nv = m.nv
        q, dq, tau_J = as_f64_c(q), as_f64_c(dq), as_f64_c(tau_J)
        if dq.shape != (nv,) or tau_J.shape != (nv,):
            dq, tau_J = (np.ascontiguousarray(np.broadcast_to(x, (nv,)), dtype=float) for x in (dq, tau_J))
        # Pinocchio hands out fresh C-ordered arrays (ascontiguousarray returns them as they are).
        M = np.ascontiguousarray(pin.crba(m, d, q))
        C = np.ascontiguousarray(pin.computeCoriolisMatrix(m, d, q, dq))
        g = np.ascontiguousarray(pin.computeGeneralizedGravity(m, d, q))
        J = np.ascontiguousarray(pin.computeFrameJacobian(m, d, q, self.model.frame_E, self._lwa))
        first = self._p0 is None
        if self._p0 is None:
            self._p0 = np.empty(nv)
        r_new = np.empty(nv)
        force = np.empty(3)
        args = (M, C, g, J, dq, tau_J, self.r, float(dt), float(self.gain), float(self.damping) ** 2, first, self._p0,
                self._integral, r_new, force)
        if self._step is None:
            self._step = bind(_observer_step, *args)
        ok = self._step(*args)
        self.r = r_new
        if not ok:
            raise np.linalg.LinAlgError("Singular matrix")
        return force

    def update_reference(self, q: np.ndarray, dq: np.ndarray, tau_J: np.ndarray, dt: float) -> np.ndarray:
        """:meth:`update` written out in numpy (the uncompiled reference the tests compare with)."""
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
