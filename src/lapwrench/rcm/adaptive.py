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
from dataclasses import dataclass, field

import numpy as np

from lapwrench.config import AdaptiveRcmConfig
from lapwrench.shaping import sine_ramp
from lapwrench.spatial import Mat, Vec


def residual_force(F_s: Vec, F_m: Vec) -> Vec:
    """Eq (19), per axis: ΔF = F_s - F_m (both in {B}; see the module docstring for signs)."""
    return F_s - F_m


def dead_zone_saturation(residual: Vec, cfg: AdaptiveRcmConfig) -> Vec:
    """Eqs (20)-(22), per axis: F_re = sgn(ΔF) Φ(|ΔF|), Φ the dead-zone / sine / saturation map."""
    return np.array(
        [
            math.copysign(sine_ramp(abs(x), cfg.gamma1, cfg.gamma2, cfg.F_op, cfg.ramp), x) if x else 0.0
            for x in np.asarray(residual, dtype=float).tolist()
        ]
    )


def lateral_component(P: Mat, F_re: Vec) -> Vec:
    """Eq (23): F_re⊥ = P(θ) F_re, the part of the residual orthogonal to the shaft."""
    return P @ F_re


def rcm_point_rate(F_re_lateral: Vec, p_R: Vec, p_R_anchor: Vec, alpha: float, beta: float) -> Vec:
    """Eq (24): ṗ_R = -α F_re⊥ - β (p_R - p_R*)."""
    return -alpha * F_re_lateral - beta * (p_R - p_R_anchor)


def gate_ramp(x: float, limit: float, soft: float) -> float:
    """Weight of one gate signal: 1 up to ``soft * limit``, a half-cosine down to 0 at ``limit``, 0 beyond."""
    lo = soft * limit
    if x <= lo:
        return 1.0
    if x >= limit:
        return 0.0
    return 0.5 * (1.0 + math.cos(math.pi * (x - lo) / (limit - lo)))


@dataclass
class MotionGate:
    """The weight w of eq (24)'s estimate-driven term from the scope's commanded motion (module docstring).

    :meth:`update` takes the twist ``[ω; v]`` of {E} in {B} (eq 33) once per tick. The accelerations
    are the derivative of the twist through a first-order filter (backward Euler, time constant
    ``gate_filter_time``); the first twist seen starts the filter at rest.
    """

    cfg: AdaptiveRcmConfig
    weight: float = 1.0
    signals: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    _twist_f: Vec | None = field(init=False, default=None)

    SIGNALS = ("angular_speed", "linear_speed", "angular_acceleration", "linear_acceleration")

    @property
    def limits(self) -> tuple[float, float, float, float]:
        """The thresholds of :attr:`signals` (rad/s, m/s, rad/s², m/s²), in :attr:`SIGNALS` order."""
        c = self.cfg
        return (c.gate_angular_speed, c.gate_linear_speed, c.gate_angular_acceleration, c.gate_linear_acceleration)

    def update(self, P: Mat, twist_E: Vec, dt: float) -> float:
        """Advance one tick; returns w ∈ [0, 1] (always 1 with ``gate: none``)."""
        cfg = self.cfg
        if cfg.gate == "none":
            self.weight = 1.0
            return 1.0
        twist = np.asarray(twist_E, dtype=float)
        accel = self._filtered_acceleration(twist, dt)
        self.signals = (_norm(P @ twist[:3]), _norm(twist[3:]), _norm(P @ accel[:3]), _norm(accel[3:]))
        w_raw = min(gate_ramp(x, lim, cfg.gate_soft) for x, lim in zip(self.signals, self.limits, strict=True))
        release = math.inf if cfg.gate_release_time == 0.0 else dt / cfg.gate_release_time
        self.weight = min(w_raw, self.weight + release)
        return self.weight

    def _filtered_acceleration(self, twist: Vec, dt: float) -> Vec:
        if self._twist_f is None:
            self._twist_f = twist.copy()
        k = dt / (self.cfg.gate_filter_time + dt)
        step = k * (twist - self._twist_f)
        self._twist_f = self._twist_f + step
        return step / dt


def _norm(v: Vec) -> float:
    return math.sqrt(float(v @ v))


@dataclass
class AdaptiveRcm:
    """The adaptive RCM point p_R and its piecewise-constant anchor p_R* (eq 24-26).

    Each :meth:`update` integrates eq (24), with its estimate-driven term weighted by the motion
    gate, with explicit Euler over ``dt``. The anchor is reset to p_R at the instants where
    ‖ṗ_R‖ <= ε (eq 25-26) and held constant in between. With adaptation disabled p_R stays at its
    initial value.
    """

    cfg: AdaptiveRcmConfig
    p_R: Vec
    p_R_anchor: Vec = field(init=False)
    velocity: Vec = field(init=False)
    anchor_updates: int = field(init=False, default=0)
    gate: MotionGate = field(init=False)

    def __post_init__(self) -> None:
        self.p_R = np.array(self.p_R, dtype=float)
        self.p_R_anchor = self.p_R.copy()
        self.velocity = np.zeros(3)
        self.gate = MotionGate(self.cfg)

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
        w = self.gate.update(P, np.zeros(6) if twist_E is None else twist_E, dt)
        if not self.cfg.enabled:
            self.velocity = np.zeros(3)
            return np.zeros(3)
        F_lat = np.zeros(3) if residual is None else lateral_component(P, dead_zone_saturation(residual, self.cfg))
        self.velocity = rcm_point_rate(w * F_lat, self.p_R, self.p_R_anchor, self.cfg.alpha, self.cfg.beta)
        if math.sqrt(self.velocity @ self.velocity) <= self.cfg.epsilon:  # eq (25)
            self.p_R_anchor = self.p_R.copy()  # eq (26)
            self.anchor_updates += 1
        self.p_R = self.p_R + dt * self.velocity
        return F_lat
