"""The adaptive RCM point (eq 19-26)."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from lapwrench.config import AdaptiveRcmConfig, ConfigError, load
from lapwrench.rcm.adaptive import AdaptiveRcm, residual_force

CFG = load().adaptive_rcm
DT = 1e-3
AXIS = np.array([0.0, 0.0, -1.0])  # scope pointing down
P = np.eye(3) - np.outer(AXIS, AXIS)


def _phi(x: float) -> float:
    """Eq (21)-(22) as printed, written out independently of the implementation."""
    eta = (x - CFG.gamma1) * math.pi / (2 * (CFG.gamma2 - CFG.gamma1))
    return CFG.F_op / 2 * (math.sin(eta) + 1)


def test_residual_sign_convention() -> None:
    # incision moved +x: the wall pushes the scope +x; the robot senses hand + wall
    hand = np.array([0.0, 1.0, 0.0])
    wall_on_scope = np.array([10.0, 0.0, 0.0])
    dF = residual_force(hand, hand + wall_on_scope)
    np.testing.assert_allclose(dF, -wall_on_scope)


def test_constant_lateral_residual_moves_the_point_at_the_law_rate() -> None:
    rcm = AdaptiveRcm(CFG, np.zeros(3))
    residual = np.array([-10.0, 0.0, 0.0])
    T = 1.0
    for _ in range(round(T / DT)):
        rcm.update(P, residual, DT)
    # eq (24) with a constant anchor: p(t) = (alpha Phi / beta)(1 - exp(-beta t)) along +x
    rate0 = CFG.alpha * _phi(10.0)
    expected = rate0 / CFG.beta * (1 - math.exp(-CFG.beta * T))
    assert rcm.p_R[0] == pytest.approx(expected, rel=2e-3)
    assert rcm.p_R[1] == 0.0 and rcm.p_R[2] == 0.0
    assert rcm.velocity[0] == pytest.approx(rate0 * math.exp(-CFG.beta * T), rel=2e-3)
    assert rcm.anchor_updates == 0


def test_axial_residual_does_not_move_the_point() -> None:
    rcm = AdaptiveRcm(CFG, np.array([0.1, 0.2, 0.3]))
    for _ in range(1000):
        rcm.update(P, 12.0 * AXIS, DT)
    np.testing.assert_allclose(rcm.p_R, [0.1, 0.2, 0.3])


def test_residual_inside_the_dead_zone_does_not_move_the_point() -> None:
    rcm = AdaptiveRcm(CFG, np.zeros(3))
    for _ in range(1000):
        rcm.update(P, np.array([4.9, -4.9, 0.0]), DT)
    np.testing.assert_allclose(rcm.p_R, 0.0)


def test_anchor_updates_only_when_the_point_is_slow() -> None:
    rcm = AdaptiveRcm(CFG, np.zeros(3))
    residual = np.array([-10.0, 0.0, 0.0])
    for _ in range(500):
        rcm.update(P, residual, DT)
        assert np.linalg.norm(rcm.velocity) > CFG.epsilon
    assert rcm.anchor_updates == 0
    np.testing.assert_allclose(rcm.p_R_anchor, 0.0)
    # residual gone: leakage pulls p_R back toward the anchor until |dp/dt| <= eps, then the anchor resets
    moved = rcm.p_R.copy()
    steps = 0
    while rcm.anchor_updates == 0:
        before = rcm.p_R.copy()
        rcm.update(P, np.zeros(3), DT)
        steps += 1
        assert steps < 200_000
    assert np.linalg.norm(rcm.velocity) <= CFG.epsilon
    np.testing.assert_allclose(rcm.p_R_anchor, before)
    assert 0 < rcm.p_R_anchor[0] < moved[0]


def test_disabled_adaptation_holds_the_point() -> None:
    rcm = AdaptiveRcm(load().replace(adaptive_rcm={"enabled": False}).adaptive_rcm, np.zeros(3))
    for _ in range(100):
        rcm.update(P, np.array([-20.0, 0.0, 0.0]), DT)
    np.testing.assert_allclose(rcm.p_R, 0.0)


def test_missing_residual_only_leaks() -> None:
    rcm = AdaptiveRcm(CFG, np.zeros(3))
    rcm.update(P, None, DT)
    np.testing.assert_allclose(rcm.p_R, 0.0)


# -- the motion gate of the estimate-driven term (issue 9, point 4) --------------------------------

WALL = np.array([-10.0, 0.0, 0.0])  # a lateral residual that moves p_R along +x


def _twist(pivot: float = 0.0, linear: float = 0.0, roll: float = 0.0) -> np.ndarray:
    """[ω; v] of {E}: pivot about x (orthogonal to the shaft), roll about the shaft, flange speed along y."""
    return np.concatenate([np.array([pivot, 0.0, 0.0]) + roll * AXIS, [0.0, linear, 0.0]])


def _run(cfg: AdaptiveRcmConfig, twists: list[np.ndarray | None]) -> AdaptiveRcm:
    rcm = AdaptiveRcm(cfg, np.zeros(3))
    for tw in twists:
        rcm.update(P, WALL, DT, tw)
    return rcm


@pytest.mark.parametrize(
    "twist",
    [
        _twist(pivot=1.01 * CFG.gate_angular_speed),
        _twist(pivot=-3.0),
        _twist(linear=1.01 * CFG.gate_linear_speed),
    ],
    ids=["pivot-just-above", "pivot-fast", "flange-just-above"],
)
def test_gate_stops_adaptation_above_a_speed_threshold(twist: np.ndarray) -> None:
    rcm = _run(CFG, [twist] * 500)
    assert rcm.gate_weight == 0.0
    np.testing.assert_allclose(rcm.p_R, 0.0)  # the anchor is p_R: the leakage has nothing to pull


@pytest.mark.parametrize(
    "twist",
    [
        _twist(pivot=0.99 * CFG.gate_soft * CFG.gate_angular_speed),
        _twist(linear=0.99 * CFG.gate_soft * CFG.gate_linear_speed),
        _twist(roll=3.0),  # rolling about the shaft is not pivoting
    ],
    ids=["pivot-below", "flange-below", "roll"],
)
def test_gate_allows_adaptation_below_the_thresholds_at_the_paper_rate(twist: np.ndarray) -> None:
    gated = _run(CFG, [twist] * 500)
    paper = _run(CFG, [None] * 500)
    assert gated.gate_weight == 1.0
    assert gated.p_R[0] > 1e-3
    np.testing.assert_array_equal(gated.p_R, paper.p_R)


def test_gate_weight_is_smooth_between_the_soft_point_and_the_threshold() -> None:
    lim, soft = CFG.gate_angular_speed, CFG.gate_soft
    weights = []
    for x in np.linspace(soft * lim, lim, 11):
        rcm = _run(CFG, [_twist(pivot=x)])
        weights.append(rcm.gate_weight)
    assert weights[0] == 1.0 and weights[-1] == pytest.approx(0.0, abs=1e-12)
    assert weights[5] == pytest.approx(0.5)
    assert all(a > b for a, b in itertools.pairwise(weights))


def test_gate_closes_on_acceleration_below_the_speed_thresholds() -> None:
    cfg = load().replace(adaptive_rcm={"gate_linear_speed": 1.0}).adaptive_rcm
    a = 2.5 * cfg.gate_linear_acceleration  # the flange accelerates at 5 m/s^2 for 40 ms
    rcm = _run(cfg, [_twist(linear=a * DT * k) for k in range(40)])
    speed, accel = rcm.gate.signals[1], rcm.gate.signals[3]
    assert speed < cfg.gate_soft * cfg.gate_linear_speed  # the speed alone would leave w = 1
    assert accel == pytest.approx(a * (1 - math.exp(-0.039 / cfg.gate_filter_time)), rel=0.05)
    assert accel > cfg.gate_linear_acceleration
    assert rcm.gate_weight == 0.0


def test_gate_reopens_no_faster_than_the_release_time_after_the_motion() -> None:
    rcm = _run(CFG, [_twist(pivot=1.0)] * 100)
    assert rcm.gate_weight == 0.0
    held = rcm.p_R.copy()
    weights = []
    for _ in range(round(1.0 / DT)):  # the pivot stops at once: a deceleration, then rest
        rcm.update(P, WALL, DT, _twist())
        weights.append(rcm.gate_weight)
    steps = np.diff([0.0, *weights])
    assert np.all(steps <= DT / CFG.gate_release_time + 1e-12)
    assert weights[round(CFG.gate_release_time / DT)] < 1.0  # the stop's deceleration held it closed a while
    assert weights[-1] == 1.0
    assert rcm.p_R[0] > held[0] + 1e-3  # adapting again


def test_paper_option_ignores_the_motion() -> None:
    paper = load().replace(adaptive_rcm={"gate": "none"}).adaptive_rcm
    fast = _run(paper, [_twist(pivot=3.0, linear=1.0)] * 500)
    at_rest = _run(paper, [None] * 500)
    assert fast.gate_weight == 1.0
    np.testing.assert_array_equal(fast.p_R, at_rest.p_R)
    # and it is eq (24) exactly: the same figure as the constant-residual test above
    rate0 = paper.alpha * _phi(10.0)
    T = 0.5
    assert fast.p_R[0] == pytest.approx(rate0 / paper.beta * (1 - math.exp(-paper.beta * T)), rel=2e-3)


def test_gate_config_is_validated() -> None:
    with pytest.raises(ConfigError, match="gate_soft"):
        load().replace(adaptive_rcm={"gate_soft": 1.5})
    with pytest.raises(ConfigError, match="gate_linear_speed"):
        load().replace(adaptive_rcm={"gate_linear_speed": 0.05})  # x 0.5 is below alpha F_op = 0.03 m/s
    with pytest.raises(ConfigError, match="gate"):
        load().replace(adaptive_rcm={"gate": "fast"})
    assert load().replace(adaptive_rcm={"gate": "none", "gate_linear_speed": 0.05}).adaptive_rcm.gate == "none"
