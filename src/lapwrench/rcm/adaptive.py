"""The adaptive RCM point (eq 19-26), with a motion gate on its estimate-driven term.

Sign convention. ``F_s`` is the force the surgeon's hand applies to the scope, measured by the
handle F/T sensor and rotated into {B}. ``F_m`` is the robot's estimate of the *total external
force acting on the end effector* (hand + trocar), in {B}. Then

    ΔF = F_s - F_m = -F_trocar

is the force the scope exerts on the incision wall. If the incision moves by +x, the wall pushes
the scope toward +x, ΔF points to -x, and ṗ_R = -α F_re⊥ moves p_R toward +x: the RCM follows
the incision. (The Franka's ``O_F_ext_hat_K`` must be mapped to this convention by its driver.)

Motion gate (issue 9, ``adaptive_rcm.gate``). A robot's estimate ``F_m`` is poor while the arm
moves fast (model and friction errors, filter lag), and eq (24) would integrate that error into
p_R. With ``gate: speed`` the law is

    ṗ_R = -w α F_re⊥ - β (p_R - p_R*),      w = min(w_raw, w_prev + dt / T_release),
    w_raw = min_i ramp(x_i / x_i,max),       ramp(r) = 1 (r <= s), ½(1 + cos π (r - s)/(1 - s)) (s < r < 1), 0 (r >= 1)

over the four signals x_i of the scope's commanded motion (the reference twist of {E}): the pivot
angular speed |P ω_E|, the flange speed |v_E|, and both of their accelerations through a
first-order filter of time constant ``gate_filter_time``. ``s`` is ``gate_soft``. The weight
closes at once and re-opens no faster than over ``gate_release_time``, so the estimate's own lag
(the momentum observer's 1/K_O) has passed before the residual drives p_R again.

Only the estimate-driven term is weighted: the leakage -β (p_R - p_R*) and the anchor rule
(eq 25-26) run unchanged. The leakage does not use the estimate, so it cannot follow a bad one;
it only pulls p_R back toward the last point where p_R rested. With the paper's β and ε the
anchor is reset whenever |p_R - p_R*| <= ε/β = 10 mm, so while the gate is closed p_R is held
in practice (it moves at most at β |p_R - p_R*|, toward a point it occupied before). ``gate:
none`` gives w = 1 always: eq (24) as printed.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from lapwrench.config import AdaptiveRcmConfig
from lapwrench.jit import kernel, kernel_inlined
from lapwrench.shaping import RampVariant, sine_ramp
from lapwrench.spatial import Mat, Vec, inner, matvec

GATE_SIGNALS = ("angular_speed", "linear_speed", "angular_acceleration", "linear_acceleration")


class AdaptiveParams(NamedTuple):
    """The adaptive-RCM configuration as one tuple of scalars for the compiled maths."""

    enabled: bool
    F_op: float
    gamma1: float
    gamma2: float
    ramp: RampVariant
    alpha: float
    beta: float
    epsilon: float
    gate: bool  # True: ``gate: speed``; False: ``gate: none`` (w = 1)
    gate_angular_speed: float
    gate_linear_speed: float
    gate_angular_acceleration: float
    gate_linear_acceleration: float
    gate_soft: float
    gate_filter_time: float
    gate_release_time: float

    @staticmethod
    def from_config(c: AdaptiveRcmConfig) -> AdaptiveParams:
        return AdaptiveParams(
            bool(c.enabled), float(c.F_op), float(c.gamma1), float(c.gamma2), c.ramp, float(c.alpha),
            float(c.beta), float(c.epsilon), c.gate == "speed", float(c.gate_angular_speed),
            float(c.gate_linear_speed), float(c.gate_angular_acceleration), float(c.gate_linear_acceleration),
            float(c.gate_soft), float(c.gate_filter_time), float(c.gate_release_time),
        )


class AdaptiveState(NamedTuple):
    """The adaptive point's state, updated in place by :func:`adaptive_rcm_step`.

    ``scalars`` = [gate weight w, acceleration filter started (0/1), anchor updates, the four gate
    signals of :data:`GATE_SIGNALS`].
    """

    p_R: Vec
    p_R_anchor: Vec
    velocity: Vec
    twist_f: Vec
    scalars: Vec

    @staticmethod
    def start(p_R: Vec) -> AdaptiveState:
        p = np.array(p_R, dtype=float)
        scalars = np.zeros(3 + len(GATE_SIGNALS))  # w, filter started, anchor updates, the gate signals
        scalars[0] = 1.0
        return AdaptiveState(p, p.copy(), np.zeros(3), np.zeros(6), scalars)


@kernel_inlined
def residual_force(F_s: Vec, F_m: Vec) -> Vec:
    """Eq (19), per axis: ΔF = F_s - F_m (both in {B}; see the module docstring for signs)."""
    return F_s - F_m


@kernel
def dead_zone_saturation(residual: Vec, gamma1: float, gamma2: float, F_op: float, ramp: RampVariant) -> Vec:
    """Eqs (20)-(22), per axis: F_re = sgn(ΔF) Φ(|ΔF|), Φ the dead-zone / sine / saturation map."""
    out = np.zeros(3)
    for i in range(3):
        x = residual[i]
        if x != 0.0:
            out[i] = math.copysign(sine_ramp(abs(x), gamma1, gamma2, F_op, ramp), x)
    return out


@kernel
def lateral_component(P: Mat, F_re: Vec) -> Vec:
    """Eq (23): F_re⊥ = P(θ) F_re, the part of the residual orthogonal to the shaft."""
    return matvec(P, F_re)


@kernel
def rcm_point_rate(F_re_lateral: Vec, p_R: Vec, p_R_anchor: Vec, alpha: float, beta: float) -> Vec:
    """Eq (24): ṗ_R = -α F_re⊥ - β (p_R - p_R*)."""
    rate = np.empty(3)
    for i in range(3):
        rate[i] = -alpha * F_re_lateral[i] - beta * (p_R[i] - p_R_anchor[i])
    return rate


@kernel
def gate_ramp(x: float, limit: float, soft: float) -> float:
    """Weight of one gate signal: 1 up to ``soft * limit``, a half-cosine down to 0 at ``limit``, 0 beyond."""
    lo = soft * limit
    if x <= lo:
        return 1.0
    if x >= limit:
        return 0.0
    return 0.5 * (1.0 + math.cos(math.pi * (x - lo) / (limit - lo)))


@kernel
def _projected_norm(P: Mat, x: Vec, start: int) -> float:
    """‖P x[start:start + 3]‖ for a 3 x 3 P (no temporary arrays)."""
    s = 0.0
    for i in range(3):
        acc = 0.0
        for j in range(3):
            acc += P[i, j] * x[start + j]
        s += acc * acc
    return math.sqrt(s)


@kernel
def _norm_at(x: Vec, start: int) -> float:
    """‖x[start:start + 3]‖."""
    return math.sqrt(x[start] * x[start] + x[start + 1] * x[start + 1] + x[start + 2] * x[start + 2])


@kernel
def gate_weight(st: AdaptiveState, P: Mat, twist: Vec, dt: float, p: AdaptiveParams) -> float:
    """The motion gate's weight w of eq (24)'s estimate-driven term (module docstring), one tick.

    The accelerations are the derivative of the twist ``[ω; v]`` of {E} through a first-order
    filter (backward Euler, time constant ``gate_filter_time``); the first twist seen starts the
    filter at rest. Updates ``st.twist_f`` and ``st.scalars`` (w, signals) in place.
    """
    sc = st.scalars
    if not p.gate:
        sc[0] = 1.0
        return 1.0
    if sc[1] == 0.0:
        st.twist_f[:] = twist
        sc[1] = 1.0
    k = dt / (p.gate_filter_time + dt)
    accel = np.empty(6)
    tf = st.twist_f
    for i in range(6):
        step = k * (twist[i] - tf[i])
        tf[i] = tf[i] + step
        accel[i] = step / dt
    sc[3] = _projected_norm(P, twist, 0)
    sc[4] = _norm_at(twist, 3)
    sc[5] = _projected_norm(P, accel, 0)
    sc[6] = _norm_at(accel, 3)
    w_raw = min(
        gate_ramp(sc[3], p.gate_angular_speed, p.gate_soft),
        gate_ramp(sc[4], p.gate_linear_speed, p.gate_soft),
        gate_ramp(sc[5], p.gate_angular_acceleration, p.gate_soft),
        gate_ramp(sc[6], p.gate_linear_acceleration, p.gate_soft),
    )
    release = math.inf if p.gate_release_time == 0.0 else dt / p.gate_release_time
    sc[0] = min(w_raw, sc[0] + release)
    return sc[0]


@kernel_inlined
def adaptive_rcm_step(
    st: AdaptiveState, P: Mat, residual: Vec, has_residual: bool, twist: Vec, dt: float, p: AdaptiveParams
) -> Vec:
    """One tick of eq (24)-(26) with the gate's weight, explicit Euler over ``dt``; updates ``st`` in place.

    The anchor is reset to p_R where ‖ṗ_R‖ <= ε (eq 25-26). Returns the mapped lateral residual
    F_re⊥ (eq 23, before the gate's weight; zeros without a residual).
    """
    w = gate_weight(st, P, twist, dt, p)
    F_lat = np.zeros(3)
    if not p.enabled:
        st.velocity[:] = 0.0
        return F_lat
    if has_residual:
        F_lat = lateral_component(P, dead_zone_saturation(residual, p.gamma1, p.gamma2, p.F_op, p.ramp))
    wF = np.empty(3)
    for i in range(3):
        wF[i] = w * F_lat[i]
    st.velocity[:] = rcm_point_rate(wF, st.p_R, st.p_R_anchor, p.alpha, p.beta)
    if math.sqrt(inner(st.velocity, st.velocity)) <= p.epsilon:  # eq (25)
        st.p_R_anchor[:] = st.p_R  # eq (26)
        st.scalars[2] += 1.0
    for i in range(3):
        st.p_R[i] = st.p_R[i] + dt * st.velocity[i]
    return F_lat


class MotionGateView:
    """Read-only view of the gate's weight, signals and thresholds (telemetry, tests)."""

    SIGNALS = GATE_SIGNALS

    def __init__(self, owner: AdaptiveRcm) -> None:
        self._owner = owner

    @property
    def weight(self) -> float:
        return float(self._owner.state.scalars[0])

    @property
    def signals(self) -> tuple[float, float, float, float]:
        s = self._owner.state.scalars
        return (float(s[3]), float(s[4]), float(s[5]), float(s[6]))

    @property
    def limits(self) -> tuple[float, float, float, float]:
        """The thresholds of :attr:`signals` (rad/s, m/s, rad/s², m/s²), in :attr:`SIGNALS` order."""
        c = self._owner.cfg
        return (c.gate_angular_speed, c.gate_linear_speed, c.gate_angular_acceleration, c.gate_linear_acceleration)


class AdaptiveRcm:
    """The adaptive RCM point p_R and its piecewise-constant anchor p_R* (eq 24-26).

    Each :meth:`update` integrates eq (24), with its estimate-driven term weighted by the motion
    gate, with explicit Euler over ``dt`` (:func:`adaptive_rcm_step`). The anchor is reset to p_R
    at the instants where ‖ṗ_R‖ <= ε (eq 25-26) and held constant in between. With adaptation
    disabled p_R stays at its initial value.
    """

    def __init__(self, cfg: AdaptiveRcmConfig, p_R: Vec) -> None:
        self.cfg = cfg
        self.params = AdaptiveParams.from_config(cfg)
        self.state = AdaptiveState.start(p_R)
        self.gate = MotionGateView(self)

    @property
    def p_R(self) -> Vec:
        return self.state.p_R

    @p_R.setter
    def p_R(self, value: Vec) -> None:
        self.state.p_R[:] = value

    @property
    def p_R_anchor(self) -> Vec:
        return self.state.p_R_anchor

    @property
    def velocity(self) -> Vec:
        return self.state.velocity

    @property
    def anchor_updates(self) -> int:
        return int(self.state.scalars[2])

    @property
    def gate_weight(self) -> float:
        """The weight w of this tick's estimate-driven term (1 with ``gate: none``)."""
        return self.gate.weight

    def update(self, P: Mat, residual: Vec | None, dt: float, twist_E: Vec | None = None) -> Vec:
        """Advance p_R by one tick; ``residual`` is ΔF (eq 19) or None when it is unavailable.

        ``twist_E`` is the commanded twist ``[ω; v]`` of {E} (eq 33) that drives the motion gate;
        None counts as a scope at rest. Returns the mapped lateral residual F_re⊥ (eq 23, before
        the gate's weight).
        """
        twist = np.zeros(6) if twist_E is None else np.asarray(twist_E, dtype=float)
        r = np.zeros(3) if residual is None else np.asarray(residual, dtype=float)
        P = np.asarray(P, dtype=float)
        return adaptive_rcm_step(self.state, P, r, residual is not None, twist, dt, self.params)
