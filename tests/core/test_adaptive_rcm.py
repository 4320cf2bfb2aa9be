"""The adaptive RCM point (eq 19-26)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lapwrench.config import load
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
