"""Prioritised saturation (motion/saturation.py): the RCM task keeps its acceleration, the limits hold."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.motion.reference_shaper import ReferenceShaper, ReferenceState
from lapwrench.motion.saturation import BOX_WIDENING, LimitRows, saturate
from lapwrench.rcm.geometry import initial_rcm_point, lateral_rcm_jacobian
from lapwrench.robot.limits import limit_usage
from lapwrench.robot.model import RobotModel
from lapwrench.virtual import DEFAULT_Q0

MODEL = RobotModel("panda")
LIM = MODEL.limits


def _random_state(rng: np.random.Generator) -> tuple[ReferenceState, np.ndarray]:
    """A reference near DEFAULT_Q0 moving at a random speed, and the RCM point on its axis."""
    q = np.clip(DEFAULT_Q0 + 0.4 * rng.standard_normal(7), LIM.position_lower + 0.06, LIM.position_upper - 0.06)
    dq = 0.3 * rng.standard_normal(7)
    ddq = 3.0 * rng.standard_normal(7)
    kin = MODEL.kinematics(q, dq)
    return ReferenceState(q, dq, ddq), initial_rcm_point(kin, 0.29, 0.8)


def _task(state: ReferenceState, p_R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    kin = MODEL.kinematics(state.q, state.dq)
    return kin.R_E[:, :2].T @ lateral_rcm_jacobian(kin, p_R), kin.M


@pytest.mark.parametrize("seed", range(40))
def test_task_acceleration_is_kept_and_every_bound_holds_when_feasible(seed: int) -> None:
    rng = np.random.default_rng(seed)
    state, p_R = _random_state(rng)
    J, M = _task(state, p_R)
    shaper = ReferenceShaper(LIM, 1e-3, 0.9, 0.05)
    lo, hi = shaper.acceleration_bounds(state)
    # a demand whose lower-priority (null-space) part is far outside the joint box
    null = np.eye(7) - np.linalg.pinv(J) @ J
    a_d = np.clip(state.ddq, lo, hi) + null @ (60.0 * rng.standard_normal(7))
    rows = LimitRows.joint_box(lo, hi, shaper.lim.acceleration)
    sat = saturate(a_d, J, M, rows)
    assert sat.feasible  # a = clip(ddq) is a feasible point: the solver must find a solution
    np.testing.assert_allclose(J @ sat.a, J @ a_d, atol=1e-9 * (1 + np.abs(J @ a_d).max()))
    tol = 2.0 * BOX_WIDENING * shaper.lim.acceleration  # the solver widens every row by BOX_WIDENING
    assert np.all(sat.a >= lo - tol) and np.all(sat.a <= hi + tol)
    assert sat.saturated  # the demand was outside the box, so something was saturated


def test_a_demand_inside_the_limits_passes_unchanged() -> None:
    state, p_R = _random_state(np.random.default_rng(1))
    J, M = _task(state, p_R)
    shaper = ReferenceShaper(LIM, 1e-3, 0.9, 0.05)
    lo, hi = shaper.acceleration_bounds(state)
    a_d = 0.5 * (lo + hi)
    sat = saturate(a_d, J, M, LimitRows.joint_box(lo, hi, shaper.lim.acceleration))
    assert sat.feasible and sat.saturated == () and np.array_equal(sat.a, a_d)


def test_an_envelope_row_against_the_task_is_dropped_and_a_joint_row_against_it_is_infeasible() -> None:
    J = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    M = np.eye(3)
    a_d = np.array([2.0, 0.0, 0.0])
    box = LimitRows.joint_box(np.full(3, -5.0), np.full(3, 5.0), np.ones(3))
    env = LimitRows(J[:1], np.array([-1.0]), np.array([1.0]), np.ones(1), ("env",), np.zeros(1, dtype=bool))
    sat = saturate(a_d, J, M, LimitRows.stack(box, env))
    assert sat.feasible and sat.dropped == ("env",)
    np.testing.assert_allclose(sat.a, a_d)
    tight = LimitRows.joint_box(np.full(3, -1.0), np.full(3, 1.0), np.ones(3))
    sat = saturate(a_d, J, M, tight)
    assert not sat.feasible
    assert np.all(np.abs(sat.a) <= 1.0)  # still inside the robot's limits


def test_an_envelope_row_compatible_with_the_task_changes_only_the_null_motion() -> None:
    J = np.array([[1.0, 0.0, 0.0]])
    M = np.diag([1.0, 2.0, 3.0])
    a_d = np.array([0.5, 4.0, -1.0])
    env = LimitRows(np.array([[0.0, 1.0, 1.0]]), np.array([-1.0]), np.array([1.0]), np.ones(1), ("env",),
                    np.zeros(1, dtype=bool))
    sat = saturate(a_d, J, M, env)
    assert sat.feasible and sat.saturated == ("env",)
    assert sat.a[0] == pytest.approx(0.5, abs=1e-12)  # the task row exactly
    assert sat.a[1] + sat.a[2] == pytest.approx(1.0, abs=1e-4)  # the envelope up to its slack


@pytest.mark.parametrize("seed", range(6))
def test_controller_references_stay_inside_the_franka_limits_under_random_demands(seed: int) -> None:
    """Random hand wrenches and grips, steps included, for 0.6 s: every reference inside the limits as
    libfranka differentiates them, and the RCM task kept to 0.5 mm on the virtual dynamics."""
    from lapwrench.virtual import HandScript, run_virtual

    rng = np.random.default_rng(seed)
    knots = rng.uniform(-40, 40, size=(7, 3))
    torques = rng.uniform(-1.5, 1.5, size=(7, 3))
    hand = HandScript(
        force=lambda t: knots[min(int(t / 0.1), 6)],
        torque=lambda t: torques[min(int(t / 0.1), 6)],
        delta=lambda t: 2.0,
    )
    cfg = load().replace(viscous={"k_t": 0.5, "k_f": 5.0})  # light damping: fast, limit-hitting motion
    ctrl, log = run_virtual(cfg, 0.6, hand=hand)
    q = np.array([r.q_ref for r in log.results])
    usage = limit_usage(q, cfg.robot.dt, ctrl.model.limits, DEFAULT_Q0)
    assert usage["position_excess"] == 0.0
    for key in ("velocity", "acceleration", "jerk"):
        assert usage[key] <= cfg.robot.limit_fraction + 1e-6, (key, usage)
    assert any(r.limits_active for r in log.results)  # the demand did hit limits
    assert max(r.rcm_error for r in log.results) < 5e-4


def test_the_controller_stops_when_the_rcm_task_cannot_be_kept() -> None:
    """Six joints forced to one acceleration by zero-width boxes leave one joint for the 2-row
    task: the controller latches ``stopping`` and reports it."""
    cfg = load()
    ctrl = Controller(cfg)
    ctrl.reset(DEFAULT_Q0)

    def frozen(state: ReferenceState, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = lo.copy(), hi.copy()
        forced = np.clip(0.5, lo[1:], hi[1:])  # inside the real bounds
        lo[1:], hi[1:] = forced, forced
        return lo, hi

    ctrl.bounds_hook = frozen
    from lapwrench.virtual import HandScript, run_virtual

    _, log = run_virtual(
        cfg, 0.3, hand=HandScript(force=lambda t: np.array([20.0, 0, 0]), delta=lambda t: 2.0), controller=ctrl
    )
    assert log.results[-1].rcm_infeasible
    assert any("cannot be kept" in e.message for e in ctrl.events)
