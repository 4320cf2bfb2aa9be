"""Prioritised saturation (motion/saturation.py): the RCM task keeps its acceleration, the limits hold."""

from __future__ import annotations

import numpy as np
import pytest
import quadprog

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.motion.qp import QP_INFEASIBLE, QP_SOLVED
from lapwrench.motion.reference_shaper import ReferenceShaper, ReferenceState
from lapwrench.motion.saturation import (
    BOX_WIDENING,
    RELAXED_CHECK_TOL,
    SLACK_WEIGHT,
    LimitRows,
    saturate,
    solve_exact,
    solve_relaxed,
)
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


def _envelope_problem(seed: int) -> tuple[np.ndarray, ...]:
    """A random 7-joint problem: SPD M, a 2-row task, a wide demand, the joint box (hard, scale 10) and
    four envelope rows (soft), the first one away from zero so the envelope often fights the box."""
    rng = np.random.default_rng(seed)
    n = 7
    A = rng.standard_normal((n, n))
    M, J, a_d = A @ A.T + 0.5 * np.eye(n), rng.standard_normal((2, n)), 20.0 * rng.standard_normal(n)
    lo_e, hi_e = -rng.uniform(0, 3, 4), rng.uniform(0, 3, 4)
    lo_e[0], hi_e[0] = 5.0, 6.0
    C = np.vstack([np.eye(n), rng.standard_normal((4, n))])
    lo, hi = np.r_[-rng.uniform(1, 15, n), lo_e], np.r_[rng.uniform(1, 15, n), hi_e]
    return M, J, a_d, C, lo, hi, np.r_[np.full(n, 10.0), rng.uniform(0.5, 3, 4)], np.arange(n + 4) < n


def _quadprog_relaxed(M: np.ndarray, J: np.ndarray, a_d: np.ndarray, C: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                      scale: np.ndarray, hard: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The relaxed level written for quadprog as the module wrote it before it was compiled."""
    n, m = a_d.shape[0], int((~hard).sum())
    G = np.zeros((n + m, n + m))
    G[:n, :n], G[n:, n:] = M, np.eye(m) * SLACK_WEIGHT * np.trace(M) / n
    Cx = np.zeros((C.shape[0], n + m))
    Cx[:, :n] = C / scale[:, None]
    Cx[np.flatnonzero(~hard), n + np.arange(m)] = 1.0
    E = np.hstack([J, np.zeros((J.shape[0], m))])
    A = np.vstack([E, Cx, Cx * np.where(np.arange(n + m) < n, -1.0, 1.0)]).T
    b = np.concatenate([J @ a_d, lo / scale - BOX_WIDENING, BOX_WIDENING - hi / scale])
    try:
        x = quadprog.solve_qp(G, np.r_[M @ a_d, np.zeros(m)], A, b, J.shape[0])[0]
    except ValueError:
        return None
    return x[:n], x[n:]


@pytest.mark.parametrize("seed", range(60))
def test_the_compiled_relaxed_level_keeps_task_and_box_at_no_more_cost_than_quadprog(seed: int) -> None:
    """The envelope gives way, the box and the task do not: solved exactly when the hard level alone
    (task and box) has a solution, at a cost no higher than quadprog's for the same problem."""
    M, J, a_d, C, lo, hi, scale, hard = _envelope_problem(seed)
    n = a_d.shape[0]
    a, slack, status = solve_relaxed(np.linalg.inv(M), M, a_d, J, C, lo, hi, scale, hard)
    _, hard_status = solve_exact(np.linalg.inv(M), a_d, J, C[:n].copy(), lo[:n].copy(), hi[:n].copy(),
                                 scale[:n].copy())
    assert status == hard_status and status in (QP_SOLVED, QP_INFEASIBLE)
    if status == QP_INFEASIBLE:
        return
    np.testing.assert_allclose(J @ a, J @ a_d, atol=1e-7 * (1 + np.abs(J @ a_d).max()))
    tol = RELAXED_CHECK_TOL * scale[:n]  # checked in the kernel: beyond it, the kernel says QP_NUMERICAL
    assert np.all(a >= lo[:n] - tol) and np.all(a <= hi[:n] + tol)
    y = C[n:] @ a / scale[n:]  # each envelope row within its bounds widened by its slack
    assert np.all(y >= lo[n:] / scale[n:] - slack - RELAXED_CHECK_TOL)
    assert np.all(y <= hi[n:] / scale[n:] + slack + RELAXED_CHECK_TOL)
    ref = _quadprog_relaxed(M, J, a_d, C, lo, hi, scale, hard)
    if ref is not None:  # quadprog also reports some of these feasible problems "inconsistent"
        w = SLACK_WEIGHT * np.trace(M) / n

        def cost(x: np.ndarray, s: np.ndarray) -> float:
            return float(0.5 * (x - a_d) @ M @ (x - a_d) + 0.5 * w * s @ s)

        assert cost(a, slack) <= cost(*ref) * (1 + 1e-7)


def test_an_envelope_pressed_into_a_corner_is_relaxed_in_the_compiled_tick(monkeypatch: pytest.MonkeyPatch) -> None:
    """A steady 3 N side push with the grip closed and two instruments in view, on the light-damping
    preset, for 15 s (the robot at its reference) drives the scope into the depth and roll walls with
    joints at their limits, where the envelope must give way (bench/tick.py's light hand, held longer):
    the compiled tick relaxes it, so the Python levels run only on ticks where the RCM task itself
    cannot be kept. The references stay inside the joint limits; the RCM error stays under 0.5 mm."""
    import lapwrench.controller
    from lapwrench.sensors import ForceTorqueReading, InstrumentObservation, RobotReading, SensorFrame, TactileReading
    from lapwrench.virtual import home_pose

    python_levels: list[bool] = []

    def spy(*args: np.ndarray) -> object:
        sat = saturate(*args)  # type: ignore[arg-type]
        python_levels.append(sat.feasible)
        return sat

    monkeypatch.setattr(lapwrench.controller, "saturate", spy)
    ctrl = Controller(load("swapped-damping"))
    ctrl.reset(home_pose("panda"))
    tactile, relaxed, rcm = TactileReading(np.full(64, 62.5)), 0, 0.0
    for k in range(15000):
        t, ref = k * ctrl.dt, ctrl.ref
        assert ref is not None
        points = np.array([[480.0 + 50 * np.sin(k * 1e-3), 300.0], [150.0, 200.0]])
        r = ctrl.tick(SensorFrame(t, ForceTorqueReading(np.array([4.0 * np.sin(t), 3.0, 0.0]), np.zeros(3), t),
                                  tactile, InstrumentObservation(points, t), RobotReading(ref.q, ref.dq, None, t)))
        relaxed += {"depth_max", "roll_range"} <= set(r.limits_active)
        rcm = max(rcm, r.rcm_error)
        lim = ctrl.model.limits
        assert np.all(r.q_ref >= lim.position_lower) and np.all(r.q_ref <= lim.position_upper)
    assert relaxed > 1000  # the corner was reached and held
    assert not any(python_levels)  # only the task's own infeasible ticks (if any) went to Python
    assert rcm < 5e-4
