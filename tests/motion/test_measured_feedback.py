"""Measured-pose feedback (motion/measured_feedback.py): the offsets follow what the robot adds."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.motion.measured_feedback import FEEDBACK_TIME, NO_AXIS, MeasuredFeedback
from lapwrench.rcm.geometry import initial_rcm_point, insertion_depth, rcm_error
from lapwrench.robot.model import RobotModel, scope_axis
from lapwrench.sensors import RobotReading, SensorFrame
from lapwrench.virtual import DEFAULT_Q0

MODEL = RobotModel("panda")
DT = 1e-3


def _setup(cap: float = 0.01) -> tuple[MeasuredFeedback, object, np.ndarray, np.ndarray]:
    kin = MODEL.kinematics(DEFAULT_Q0, np.zeros(7))
    p_R = initial_rcm_point(kin, 0.29, 0.8)
    return MeasuredFeedback(MODEL, 0.29, DT, cap), kin, p_R, rcm_error(kin, p_R)


def test_offsets_converge_to_measured_minus_reference_with_the_time_constant() -> None:
    fb, kin, p_R, e_R = _setup()
    q_meas = DEFAULT_Q0 + np.array([0.004, -0.003, 0.0, 0.002, 0.0, 0.0, 0.0])
    axis = MODEL.scope_axis_at(q_meas)
    e_target = rcm_error(axis, p_R) - e_R  # type: ignore[arg-type]
    d_target = insertion_depth(axis, p_R, 0.29) - insertion_depth(kin, p_R, 0.29)  # type: ignore[arg-type]
    assert np.linalg.norm(e_target) > 1e-3  # the perturbation really moves the axis
    n = round(FEEDBACK_TIME / DT)
    for _ in range(n):
        fb.update(q_meas, kin, p_R, e_R)
    # one time constant: 1 - (1 - dt/T)^n ≈ 63 %
    frac = 1.0 - (1.0 - DT / FEEDBACK_TIME) ** n
    np.testing.assert_allclose(fb.e_offset, frac * e_target, rtol=1e-9)
    assert fb.depth_offset == pytest.approx(frac * d_target, rel=1e-9)
    for _ in range(20 * n):
        fb.update(q_meas, kin, p_R, e_R)
    np.testing.assert_allclose(fb.e_offset, e_target, atol=1e-9)


@pytest.mark.parametrize("bad", [None, np.full(7, np.nan), np.r_[DEFAULT_Q0[:6], np.inf]])
def test_a_missing_or_non_finite_measurement_lets_the_offsets_decay(bad: np.ndarray | None) -> None:
    fb, kin, p_R, e_R = _setup()
    q_meas = DEFAULT_Q0 + 0.004
    for _ in range(200):
        fb.update(q_meas, kin, p_R, e_R)
    before = np.linalg.norm(fb.e_offset)
    for _ in range(200):
        fb.update(bad, kin, p_R, e_R)
    assert np.isfinite(fb.e_offset).all() and np.isfinite(fb.depth_offset)
    assert np.linalg.norm(fb.e_offset) < 0.01 * before


def test_the_offsets_are_capped() -> None:
    fb, kin, p_R, e_R = _setup(cap=0.002)
    q_meas = DEFAULT_Q0 + 0.05  # far off the reference: a robot that is not following
    for _ in range(500):
        fb.update(q_meas, kin, p_R, e_R)
    assert np.linalg.norm(fb.e_offset) <= 0.002 + 1e-12
    assert abs(fb.depth_offset) <= 0.002 + 1e-12


def test_the_controller_leans_the_reference_against_a_measured_deflection() -> None:
    """A robot that sits 3 mrad off the reference on joint 1: the reference moves until the measured
    RCM error is small, while the reference's own error grows to about the deflection."""
    ctrl = Controller(load())
    ctrl.reset(DEFAULT_Q0)
    offset = np.array([0.003, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    p_R = ctrl.rcm.p_R.copy()  # type: ignore[union-attr]
    res = None
    for k in range(1500):
        assert ctrl.ref is not None
        q_meas = ctrl.ref.q + offset
        res = ctrl.tick(SensorFrame(k * DT, robot=RobotReading(q_meas, ctrl.ref.dq, None, k * DT)))
    assert res is not None
    e_meas = np.linalg.norm(rcm_error(MODEL.scope_axis_at(res.q_ref + offset), p_R))  # type: ignore[arg-type]
    e_open = np.linalg.norm(rcm_error(MODEL.scope_axis_at(DEFAULT_Q0 + offset), p_R))  # type: ignore[arg-type]
    assert e_open > 5e-4
    assert e_meas < 0.1 * e_open
    assert res.rcm_error > 0.5 * e_open


def test_the_placement_the_compiled_tick_reads_gives_the_measured_axis() -> None:
    """The one-call tick takes the measured axis from {E}'s placement (scope_axis inside the kernel); it
    must be the axis :meth:`RobotModel.scope_axis_at` gives, and the identity without a measurement."""
    fb = MeasuredFeedback(MODEL, 0.29, DT, 0.01)
    q_meas = DEFAULT_Q0 + np.array([0.01, -0.02, 0.0, 0.03, 0.0, 0.01, 0.0])
    R, p, has = fb.measured_placement(q_meas)
    want = MODEL.scope_axis_at(q_meas)
    d_z, P = scope_axis(R)
    assert has
    np.testing.assert_array_equal(p, want.p_E)
    np.testing.assert_array_equal(d_z, want.d_z)
    np.testing.assert_array_equal(P, want.P)
    R0, p0, has0 = fb.measured_placement(None)
    assert not has0 and not p0.any()
    np.testing.assert_array_equal(scope_axis(R0)[1], NO_AXIS.P)
