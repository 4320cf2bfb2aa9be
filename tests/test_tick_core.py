"""The compiled tick's stages (lapwrench.tick_core) against the equation functions they compose, on random
states (moved poses, random velocities, every sensor on), and what they promise for non-finite input: a
non-finite fused torque is zeroed and flagged, a non-finite demand is never solved by the compiled saturation
step. The argument types are those the controller binds: nothing here compiles a new signature."""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np
import pytest

from lapwrench import allocation as al
from lapwrench import tick_core as tc
from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.motion import virtual_model as vm
from lapwrench.motion.envelope import envelope_rows
from lapwrench.motion.reference_shaper import acceleration_bounds, advance_reference
from lapwrench.motion.saturation import VIOLATION_TOL, at_bound, solve_exact, solve_relaxed
from lapwrench.rcm import geometry as rg
from lapwrench.rcm.adaptive import AdaptiveState, adaptive_rcm_step, residual_force
from lapwrench.robot.model import Kinematics, ScopeAxis, assemble_kinematics, inverse_inertia
from lapwrench.virtual import home_pose
from lapwrench.wrenches.ft_zero import FtTare, conditioned_ft
from lapwrench.wrenches.interaction import grip_gain, interaction_wrench
from lapwrench.wrenches.rcm import rcm_feedforward, rcm_force
from lapwrench.wrenches.tracking import virtual_force

SEEDS = range(6)
NO_EXTRA = (np.zeros((0, 6)), np.zeros((0, 3)), np.zeros((6, 6)), np.zeros(3))
# what the Python cues add: one null-space cue's wrench and its point, its damping, a task-space force
EXTRA = (np.array([[0.0, 0.1, 0.0, 1.0, -2.0, 3.0]]), np.array([[0.5, 0.0, 0.3]]), 0.5 * np.eye(6),
         np.array([0.0, 1.5, 0.0]))


@pytest.fixture(scope="module")
def ctrl() -> Controller:
    c = Controller(cfg := load())
    c.reset(home_pose(cfg.robot.kind))
    return c


def close(a: Any, b: Any, what: str) -> None:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    scale = max(1.0, float(np.abs(b).max(initial=0.0)))
    np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-9 * scale, err_msg=what)


def R_E0(ctrl: Controller) -> np.ndarray:
    """{E}'s orientation at the reset (the envelope's roll is measured from it)."""
    return ctrl.envelope.R_E0  # type: ignore[return-value]


def copied(state: AdaptiveState) -> AdaptiveState:
    return AdaptiveState(*(a.copy() for a in state))


class Readings(NamedTuple):
    ft_force: np.ndarray
    ft_torque: np.ndarray
    has_ft: bool
    tactile: np.ndarray
    has_tactile: bool
    points: np.ndarray


def readings(rng: np.random.Generator, *, grip: bool = True) -> Readings:
    tactile = rng.uniform(0.0, 255.0, 64) * (rng.random(64) < (0.7 if grip else 0.0))
    points = rng.uniform([0.0, 0.0], [640.0, 480.0], (int(rng.integers(1, 4)), 2))
    return Readings(rng.uniform(-30.0, 30.0, 3), rng.uniform(-1.0, 1.0, 3), True, tactile, True, points)


# tick_front's outputs, the adaptive state and offsets before it stepped them, assemble_kinematics of its terms
class Front(NamedTuple):
    kin: Kinematics
    geo: Any
    F_lat: np.ndarray
    residual: np.ndarray
    has_residual: bool
    state_before: AdaptiveState
    offsets_before: np.ndarray
    assembled: Kinematics


def front(ctrl: Controller, rng: np.random.Generator, *, has_ft: bool = True, has_ext: bool = True,
          speed: float = 0.4, move: float = 0.15) -> Front:
    """tick_front at a random moved pose and velocity (copies of the controller's state)."""
    assert ctrl.ref is not None and ctrl.rcm is not None
    n = ctrl.ref.q.shape[0]
    q, dq = ctrl.ref.q + rng.uniform(-move, move, n), rng.uniform(-speed, speed, n)
    R_m, p_m = (a.copy() for a in ctrl.model.placement_E_into(q + rng.normal(0.0, 2e-3, n)))
    terms = ctrl.model.terms(q, dq)
    state = copied(ctrl.rcm.state)
    state.p_R[:] += rng.normal(0.0, 2e-3, 3)  # the point away from the pivot: a non-zero e_R
    offsets = rng.normal(0.0, 1e-3, 4)
    before, off_before = copied(state), offsets.copy()
    ext, force = rng.uniform(-10.0, 10.0, 3), rng.uniform(-10.0, 10.0, 3)
    out = tc.tick_front(terms, state, ctrl.rcm.params, ext, has_ext, offsets, R_m, p_m, True, force, np.zeros(3),
                        has_ft, np.zeros(64), False, FtTare.at(np.eye(3)), ctrl.params)
    return Front(*out[:5], before, off_before, assemble_kinematics(*terms))


def motion(ctrl: Controller, f: Front, r: Readings, *, stopping: bool = False, extra: bool = False,
           kin: Kinematics | None = None) -> tc.MotionOutput:
    kin, ex = f.kin if kin is None else kin, EXTRA if extra else NO_EXTRA
    return tc.motion_stage(kin, inverse_inertia(kin.M), f.geo, *r, *ex, np.zeros(kin.q.shape[0]), stopping, R_E0(ctrl),
                           0.0, ctrl.params)


@pytest.mark.parametrize(("has_ft", "has_ext"), [(True, True), (True, False), (False, True)])
def test_tick_front_is_the_kinematics_the_residual_and_the_geometry_of_eq_19_to_36(
    ctrl: Controller, has_ft: bool, has_ext: bool
) -> None:
    p = ctrl.params
    assert ctrl.rcm is not None
    for rng in map(np.random.default_rng, SEEDS):
        f = front(ctrl, rng, has_ft=has_ft, has_ext=has_ext)
        kin, geo = f.kin, f.geo
        for name, a, b in zip(Kinematics._fields, kin, f.assembled, strict=True):  # Pinocchio's terms, assembled
            close(a, b, name)
        # ΔF (eq 19) only when both the F/T and the robot's estimate are valid, else zero
        assert f.has_residual == (has_ft and has_ext) and (f.has_residual or not np.any(f.residual))
        # the adaptive point: one step of eq (24)-(26) from the state before (its own function)
        state = copied(f.state_before)
        F_lat = adaptive_rcm_step(state, kin.P, f.residual, f.has_residual, kin.J_E @ kin.dq, p.dt, ctrl.rcm.params)
        close(np.r_[f.F_lat, geo.p_R, geo.rcm_velocity], np.r_[F_lat, state.p_R, state.velocity], "F_lat, p_R, ṗ_R")
        # eq (27) and the task geometry (eq 28-36), each from its own function
        close(geo.e_R, rg.rcm_error(kin, geo.p_R), "e_R")
        J_R = rg.lateral_rcm_jacobian(kin, geo.p_R) if p.lateral else rg.rcm_jacobian(kin, geo.p_R)
        close(geo.J_R, J_R, "J_R")
        close(geo.e_R_rate, rg.rcm_error_rate(kin, J_R, geo.rcm_velocity), "e_R rate")
        s_star = rg.closest_point_parameter(kin, geo.p_R, p.length)
        p_G, o_G = rg.closest_point(kin, s_star, p.length)
        close(np.r_[geo.s_star, geo.p_G, geo.o_G], np.r_[s_star, p_G, o_G], "s*, p_G, o_G")
        close(geo.J_G, rg.closest_point_jacobian(kin, o_G), "J_G")
        # p_G lies on the scope axis, between {E} and the tip
        assert 0.0 <= geo.s_star <= 1.0  # eq (29)-(30): a fraction of the scope length
        close(np.cross(geo.p_G - kin.p_E, kin.d_z), np.zeros(3), "p_G on the axis")


def test_geometry_stage_steps_the_state_in_place_and_returns_the_mapped_residual(ctrl: Controller) -> None:
    """The stage on its own: the state and the offsets are stepped in place, like tick_front's."""
    assert ctrl.rcm is not None
    f = front(ctrl, np.random.default_rng(3))
    kin, state, offsets = f.kin, copied(f.state_before), f.offsets_before.copy()
    measured = ScopeAxis(kin.p_E + 1e-3, kin.d_z.copy(), kin.P.copy())  # 1 mm off the reference axis
    geo, F_lat = tc.geometry_stage(kin, state, ctrl.rcm.params, f.residual, True, offsets, measured, True, ctrl.params)
    assert not np.array_equal(offsets, f.offsets_before)  # the measured axis moved the offsets
    close(geo.e_R_offset, offsets[:3], "the geometry carries the offsets' e_R part")
    close(np.r_[geo.p_R, geo.rcm_velocity], np.r_[state.p_R, state.velocity], "the stepped state's point")
    twist, again = kin.J_E @ kin.dq, copied(f.state_before)
    close(F_lat, adaptive_rcm_step(again, kin.P, f.residual, True, twist, ctrl.params.dt, ctrl.rcm.params), "F_lat")
    close(state.p_R, again.p_R, "p_R of eq (24)-(26)")
    state_b, offsets_b = copied(f.state_before), f.offsets_before.copy()
    tc.geometry_stage(kin, state_b, ctrl.rcm.params, f.residual, True, offsets_b, measured, False, ctrl.params)
    assert np.all(np.abs(offsets_b) <= np.abs(f.offsets_before) + 1e-15)  # without a measurement: decay


def expected_motion(ctrl: Controller, f: Front, r: Readings, stopping: bool, extra: bool) -> dict[str, Any]:
    """motion_stage rebuilt from the equation functions (eq 2-14, 37-40) and the virtual model's."""
    p, kin, geo = ctrl.params, f.kin, f.geo
    n, Minv = kin.q.shape[0], inverse_inertia(kin.M)
    J_pinv = al.weighted_pseudo_inverse(geo.J_R, Minv, *([kin.d_z] if p.lateral else []))
    F_r = rcm_force(geo.e_R + geo.e_R_offset, geo.e_R_rate, p.Kp, p.Kd)
    if p.rcm_feedforward:
        J_lat = rg.lateral_rcm_jacobian(kin, geo.p_R)
        F_r = F_r + rcm_feedforward(kin, Minv, J_lat, al.weighted_pseudo_inverse(J_lat, Minv, kin.d_z),
                                    rg.rcm_error_drift(kin, geo.p_R, geo.rcm_velocity))
    delta, contacts = grip_gain(r.tactile, p.k_H, p.k_min, p.contact_threshold)
    W_h = (np.r_[interaction_wrench(r.ft_force, r.ft_torque, kin.R_H, delta)] if p.cue_interaction and delta != 0.0
           else np.zeros(6))
    W_c = np.r_[np.zeros(3), virtual_force(r.points, p.tracking, kin.R_C)] if p.cue_tracking else np.zeros(6)
    D = (p.D_guided if delta > 0.0 else p.D_unguided) if p.cue_viscous else np.zeros((6, 6))
    W_f = -D @ (geo.J_G @ kin.dq)
    W_x, P_x, D_extra, task_F = EXTRA if extra else NO_EXTRA
    W_n = al.nullspace_wrench(np.vstack([W_h, W_c, W_f, W_x]), np.vstack([kin.p_H, kin.p_C, geo.p_G, P_x]), geo.p_G)
    N_r = al.nullspace_projector(geo.J_R, J_pinv)
    tau_n = np.zeros(n) if stopping else al.nullspace_torque(geo.J_G, W_n)
    tau = al.task_priority_torque(geo.J_R, F_r + task_F, N_r, tau_n)
    N_E_T = vm.self_motion_projector(kin, Minv)
    B_self = vm.self_motion_damping(kin, N_E_T, p.self_motion_damping)
    push = (vm.joint_limit_torque(kin.q, p.q_lo, p.q_hi, p.joint_limit_zone, p.joint_limit_stiffness)
            if p.joint_limit_stiffness != 0.0 else np.zeros(n))
    vm.add_self_motion_torque(tau, N_E_T, push, B_self, kin.dq)
    B = vm.damping_jacobian(geo.J_R, p.Kd, N_r, geo.J_G, D + D_extra, B_self)
    a_d = (vm.euler_velocity_step(kin, tau, B, p.dt, p.integrator) - kin.dq) / p.dt
    J_task = rg.lateral_task(kin.R_E, geo.J_R)
    if stopping:
        a_d = a_d - tc.null_brake(J_task, Minv, kin.dq, p.stop_time)
    a_lo, a_hi = acceleration_bounds(kin.q, kin.dq, np.zeros(n), p.q_lo, p.q_hi, p.v_max, p.a_max, p.j_max, p.dt)
    env = envelope_rows(kin, geo.p_R, a_d, 0.0, R_E0(ctrl), p.envelope, p.length, p.dt)
    return {"W_r": np.r_[np.zeros(3), F_r], "W_h": W_h, "W_c": W_c, "W_f": W_f, "W_n": W_n, "delta": delta,
            "contacts": contacts, "tau": tau, "a_d": a_d, "a_lo": a_lo, "a_hi": a_hi, "J_task": J_task,
            **dict(zip(("env_W", "env_lo", "env_hi", "env_scale", "env_wall"), env, strict=True))}


@pytest.mark.parametrize(("stopping", "extra"), [(False, False), (True, False), (False, True)],
                         ids=["running", "stopping", "python-cue"])
def test_motion_stage_composes_the_equations(ctrl: Controller, stopping: bool, extra: bool) -> None:
    p = ctrl.params
    assert p.rcm_feedforward  # the default: the RCM force includes the feed-forward (wrenches/rcm.py)
    assert p.cue_interaction and p.cue_tracking and p.cue_viscous  # the default configuration fuses the three
    wrenches_seen = np.zeros(4)
    for rng in map(np.random.default_rng, SEEDS):
        f, r = front(ctrl, rng), readings(rng)
        o = motion(ctrl, f, r, stopping=stopping, extra=extra)
        for key, value in expected_motion(ctrl, f, r, stopping, extra).items():
            close(getattr(o, key), value, key)
        assert not o.non_finite
        wrenches_seen += [np.abs(w).max() for w in (o.W_r, o.W_h, o.W_c, o.W_f)]
        # eq (14) by hand, F_r = -Kp e - Kd ė, plus the feed-forward: a force across the shaft only
        F_ff = o.W_r[3:] - (-p.Kp * (f.geo.e_R + f.geo.e_R_offset) - p.Kd * f.geo.e_R_rate)
        close(F_ff @ f.kin.d_z, 0.0, "eq 14 + F_ff across the shaft")
        assert np.abs(F_ff).max() > 1e-6  # the random joint speeds make velocity products
        # admitted iff a_d meets the joint box (and the envelope rows, checked like the stage)
        box_ok = bool(np.all(np.maximum(o.a_lo - o.a_d, o.a_d - o.a_hi) / p.a_max <= VIOLATION_TOL))
        y = o.env_W @ (f.kin.J_E @ o.a_d)
        env_ok = bool(np.all(np.maximum(o.env_lo - y, y - o.env_hi) / o.env_scale <= VIOLATION_TOL))
        assert o.admitted == (box_ok and (env_ok or not p.envelope_enabled))
    assert np.all(wrenches_seen > 0.0)  # every wrench acted on some state


def test_null_brake_decelerates_the_null_space_motion_only(ctrl: Controller) -> None:
    for f in (front(ctrl, np.random.default_rng(seed)) for seed in SEEDS):
        Minv, J, dq = inverse_inertia(f.kin.M), rg.lateral_task(f.kin.R_E, f.geo.J_R), f.kin.dq
        b, J_pinv = tc.null_brake(J, Minv, dq, 0.5), al.weighted_pseudo_inverse(J, Minv)
        close(J @ b, np.zeros(2), "no task acceleration")
        close(b, (dq - J_pinv @ (J @ dq)) / 0.5, "N dq / T (eq 3-4)")
        close(tc.null_brake(J, Minv, J_pinv @ (J @ dq), 0.5), np.zeros(dq.shape[0]), "task motion: no brake")


@pytest.mark.parametrize(("bad", "i"), [("ft_force", 0), ("ft_force", 2), ("ft_torque", 2), ("tactile", 5)])
def test_a_non_finite_reading_gives_a_zero_torque_flagged_non_finite(ctrl: Controller, bad: str, i: int) -> None:
    """The validator rejects such readings before the tick; should one reach the stage, the fused torque is
    not finite and the stage replaces it by zero (braking) and says so."""
    rng = np.random.default_rng(12)
    f, r = front(ctrl, rng), readings(rng)
    assert grip_gain(r.tactile, ctrl.params.k_H, ctrl.params.k_min, ctrl.params.contact_threshold)[0] > 0.0
    assert not motion(ctrl, f, r).non_finite
    value = getattr(r, bad).copy()
    value[i] = np.nan
    o = motion(ctrl, f, r._replace(**{bad: value}))
    assert o.non_finite and not np.any(o.tau)
    assert np.all(np.isfinite(o.a_d))  # the virtual model integrated with zero torque: a finite brake


def test_a_non_finite_value_the_equations_do_not_read_changes_nothing(ctrl: Controller) -> None:
    """Eq (6) keeps only the axial torque; a detection at NaN pixels adds no tracking force (eq 10); without
    a grip the F/T reading is not read at all."""
    rng = np.random.default_rng(12)
    f, r = front(ctrl, rng), readings(rng)
    good = motion(ctrl, f, r)
    o = motion(ctrl, f, r._replace(ft_torque=np.r_[np.nan, np.nan, r.ft_torque[2]]))
    assert not o.non_finite
    close(o.tau, good.tau, "tau")
    o = motion(ctrl, f, r._replace(points=np.vstack([r.points, [np.nan, 100.0]])))
    assert not o.non_finite
    close(o.W_c, good.W_c, "tracking wrench without the NaN detection")
    r = readings(rng, grip=False)  # no grip: no handle wrench (eq 7: δ = 0), the unguided viscous one
    for o in motion(ctrl, f, r), motion(ctrl, f, r._replace(has_ft=False, has_tactile=False)):
        assert o.delta == 0.0 and o.contacts == 0 and not np.any(o.W_h)
        close(o.W_f, -ctrl.params.D_unguided @ (f.geo.J_G @ f.kin.dq), "unguided viscous wrench")


def test_a_mass_matrix_that_is_not_positive_definite_is_flagged_not_raised(ctrl: Controller) -> None:
    """inverse_inertia's promise: M not positive definite gives M⁻¹ = NaN, 'so the tick's non-finite guard
    sees it' (tau zero and flagged, a finite reference), rather than an exception out of the compiled tick."""
    f = front(ctrl, rng := np.random.default_rng(13))
    kin = f.kin._replace(M=-np.eye(f.kin.q.shape[0]))
    assert np.all(np.isnan(inverse_inertia(kin.M)))
    try:
        o = motion(ctrl, f, readings(rng), kin=kin)
    except AssertionError as exc:  # numba's internal error (not an assertion of this test)
        raise RuntimeError(f"the compiled stage raised: {exc}") from exc
    assert o.non_finite and not np.any(o.tau)


def saturating(ctrl: Controller, seed: int) -> tuple[Front, tc.MotionOutput, tc.SaturationInputs]:
    """A tick near rest pushed hard by its readings: the desired acceleration breaks the joint box (the
    jerk limit from rest), and the saturation inputs for it."""
    rng = np.random.default_rng(seed)
    f = front(ctrl, rng, speed=0.05, move=0.05)
    o = motion(ctrl, f, readings(rng))
    assert not o.admitted
    sat = tc.SaturationInputs.allocate(f.kin.q.shape[0])
    tc.fill_saturation_inputs(sat, o, f.kin, ctrl.params.a_max)
    return f, o, sat


def test_fill_saturation_inputs_stacks_the_joint_box_over_the_envelope_rows(ctrl: Controller) -> None:
    f, o, sat = saturating(ctrl, 16)
    n = f.kin.q.shape[0]
    assert sat.C.shape == (n + 4, n) and sat.lo.shape == (n + 4,) and sat.J_task.shape == (2, n)
    sat.C[:] = 7.0  # stale values of an earlier tick are overwritten
    tc.fill_saturation_inputs(sat, o, f.kin, ctrl.params.a_max)
    close(sat.C, np.r_[np.eye(n), o.env_W @ f.kin.J_E], "joint rows over the envelope rows through J_E")
    for got, want in ((sat.lo, np.r_[o.a_lo, o.env_lo]), (sat.hi, np.r_[o.a_hi, o.env_hi]), (sat.a_d, o.a_d),
                      (sat.scale, np.r_[ctrl.params.a_max, o.env_scale]), (sat.M, f.kin.M), (sat.J_task, o.J_task),
                      (sat.wall, o.env_wall)):
        np.testing.assert_array_equal(got, want)


def test_saturation_stage_meets_the_box_and_keeps_the_rcm_task(ctrl: Controller) -> None:
    """Every row hard where that has a solution, else the envelope relaxed (solve_relaxed): the box is met
    and the task kept either way; where the task cannot be kept (near rest, the jerk limit leaves a
    narrow box), the step is left to Python. The relaxed case: the next test, and tests/motion."""
    p = ctrl.params
    exact_seen = refused_seen = 0
    for seed in range(20, 28):
        f, _, sat = saturating(ctrl, seed)
        n, Minv = f.kin.q.shape[0], inverse_inertia(f.kin.M)
        m = n + 4 if p.envelope_enabled else n
        rows = (sat.C[:m], sat.lo[:m], sat.hi[:m], sat.scale[:m])
        a_qp, status = solve_exact(Minv, sat.a_d, sat.J_task, *rows)
        if status != 0:  # no solution with every row hard: the envelope gives way
            a_qp, _, status = solve_relaxed(Minv, sat.M, sat.a_d, sat.J_task, *rows, np.arange(m) < n)
        else:
            exact_seen += 1
        solved, ref, at, clamped = tc.saturation_stage(sat, Minv, f.kin.q, f.kin.dq, p)
        assert solved == (status == 0)
        if not solved:
            refused_seen += 1
            assert not np.any(ref) and not np.any(at)
            continue
        a, tol = ref[2], 2e-6 * p.a_max  # rows widened by a fraction of their scale
        assert np.all(a >= sat.lo[:n] - tol) and np.all(a <= sat.hi[:n] + tol)
        close(sat.J_task @ a_qp, sat.J_task @ sat.a_d, "the RCM task's acceleration is kept")
        assert np.all(np.abs(a - a_qp) <= tol)  # the reference clips only the widening off
        q1, dq1, a1, clamped1 = advance_reference(f.kin.q, f.kin.dq, a_qp, sat.lo[:n], sat.hi[:n], p.dt)
        close(ref, np.array([q1, dq1, a1]), "the next reference of the QP's acceleration")
        assert clamped == clamped1
        np.testing.assert_array_equal(at[:m], at_bound(*rows, a_qp))
        assert at[:m].any()  # some limit binds
    assert exact_seen > 0 and refused_seen > 0


def test_saturation_stage_relaxes_impossible_envelope_rows_and_refuses_the_rest(ctrl: Controller) -> None:
    f, _, sat = saturating(ctrl, 24)
    n, Minv, p = f.kin.q.shape[0], inverse_inertia(f.kin.M), ctrl.params
    assert tc.saturation_stage(sat, Minv, f.kin.q, f.kin.dq, p)[0]
    sat.lo[n:], sat.hi[n:] = 1.0, -1.0  # envelope rows no acceleration could meet: they give way
    solved, ref, at, _ = tc.saturation_stage(sat, Minv, f.kin.q, f.kin.dq, p)
    assert solved and at[n:n + 4].all() and np.all(np.isfinite(ref))
    assert np.all(ref[2] >= sat.lo[:n] - 2e-6 * p.a_max) and np.all(ref[2] <= sat.hi[:n] + 2e-6 * p.a_max)
    solved, ref, at, _ = tc.saturation_stage(sat, Minv, f.kin.q, f.kin.dq, p._replace(envelope_enabled=False))
    assert solved and not at[n:].any() and np.all(np.isfinite(ref))
    sat.hi[:n] = sat.lo[:n] - 1.0  # and a joint box hi below lo: the task cannot be kept, left to Python
    for params in (p, p._replace(envelope_enabled=False)):
        solved, ref, at, clamped = tc.saturation_stage(sat, Minv, f.kin.q, f.kin.dq, params)
        assert not solved and not clamped and not np.any(ref) and not np.any(at)
    _, _, sat = saturating(ctrl, 24)
    sat.a_d[2] = np.inf  # a non-finite demand: left to the Python levels
    solved, ref, at, clamped = tc.saturation_stage(sat, Minv, f.kin.q, f.kin.dq, p)
    assert not solved and not clamped and not np.any(ref) and not np.any(at)


def tail(ctrl: Controller, f: Front, r: Readings, may_admit: bool, sat: tc.SaturationInputs) -> tuple[Any, ...]:
    return tc.motion_tail(f.kin, f.geo, *r, *NO_EXTRA, np.zeros(f.kin.q.shape[0]), False, R_E0(ctrl), 0.0, may_admit,
                          sat, ctrl.params)


def test_motion_tail_admits_or_hands_the_saturation_inputs_over(ctrl: Controller) -> None:
    rng = np.random.default_rng(30)
    admitted_seen = refused_seen = 0
    for k in range(8):
        f = front(ctrl, rng, speed=0.4 * (k % 2), move=0.15 * (k % 2))  # at rest, no grip: admitted
        r = readings(rng, grip=k % 2 == 1)
        n, o, sat = f.kin.q.shape[0], motion(ctrl, f, r), tc.SaturationInputs.allocate(f.kin.q.shape[0])
        W, ref, at_mask, delta, contacts, non_finite, admitted, saturated, clamped = tail(ctrl, f, r, True, sat)
        close(W, np.array([o.W_r, o.W_h, o.W_c, o.W_f, o.W_n]), "W rows")
        close(ref[3], o.tau, "tau row")
        assert (delta, contacts, non_finite, admitted) == (o.delta, o.contacts, o.non_finite, o.admitted)
        if admitted:
            admitted_seen += 1
            want = advance_reference(f.kin.q, f.kin.dq, o.a_d, o.a_lo, o.a_hi, ctrl.params.dt)
            close(ref[:3], np.array(want[:3]), "the admitted reference")
            assert not saturated and at_mask == 0 and clamped == want[3]
        else:
            refused_seen += 1
            close(sat.a_d, o.a_d, "saturation inputs")
        sat2 = tc.SaturationInputs.allocate(n)  # may_admit False: never a reference, the saturation inputs
        _, ref2, mask2, _, _, _, admitted2, saturated2, _ = tail(ctrl, f, r, False, sat2)
        assert not admitted2 and not saturated2 and mask2 == 0 and not np.any(ref2[:3])
        close(np.r_[sat2.a_d, sat2.C[:n].ravel()], np.r_[o.a_d, np.eye(n).ravel()], "saturation inputs")
    assert admitted_seen > 0 and refused_seen > 0


def test_tick_stage_is_tick_front_then_motion_tail(ctrl: Controller) -> None:
    """The one-call tick, with the argument types the controller binds (Pinocchio's layouts)."""
    assert ctrl.rcm is not None and ctrl.ref is not None
    rng, p, n = np.random.default_rng(40), ctrl.params, ctrl.ref.q.shape[0]
    for _ in range(4):
        q, dq = ctrl.ref.q + rng.uniform(-0.1, 0.1, n), rng.uniform(-0.3, 0.3, n)
        r, ext, offsets = readings(rng), rng.uniform(-5.0, 5.0, 3), np.r_[rng.normal(0.0, 1e-3, 3), 0.0]
        state_a, state_b, off_a, off_b = copied(ctrl.rcm.state), copied(ctrl.rcm.state), offsets.copy(), offsets.copy()
        tare_a = FtTare(ctrl.model.kinematics(ctrl.ref.q, np.zeros(n)).R_H, rng.normal(0.0, 0.1, 6))
        tare_b = FtTare(tare_a.R_H0, tare_a.zero.copy())
        R_m, p_m, _ = ctrl.feedback.measured_placement(q)
        got = tc.tick_stage(ctrl.model.terms(q, dq), state_a, ctrl.rcm.params, ext, True, off_a, R_m, p_m, True,
                            r.ft_force, r.ft_torque, True, r.tactile, True, r.points, np.zeros(n), False, R_E0(ctrl),
                            True, tc.SaturationInputs.allocate(n), tare_a, p)
        R_m, p_m, _ = ctrl.feedback.measured_placement(q)
        kin, geo, F_lat, residual, has_residual, force, torque = tc.tick_front(
            ctrl.model.terms(q, dq), state_b, ctrl.rcm.params, ext, True, off_b, R_m.copy(), p_m.copy(), True,
            r.ft_force, r.ft_torque, True, r.tactile, True, tare_b, p)
        want_tail = tc.motion_tail(kin, geo, force, torque, *r[2:], *NO_EXTRA, np.zeros(n), False, R_E0(ctrl),
                                   off_b[3], True, tc.SaturationInputs.allocate(n), p)
        close(got[0], np.array([geo.e_R, geo.p_R, geo.p_G, F_lat, residual]), "vec3 rows")
        assert got[1] == has_residual is True
        close(residual, residual_force(kin.R_H @ force, ext), "ΔF = R_H F_s - F_ext (eq 19), of the hand's force")
        for i, (a, b) in enumerate(zip(got[2:], want_tail, strict=True)):
            close(a, b, f"output {i}")
        for name, a, b in zip(AdaptiveState._fields, state_a, state_b, strict=True):
            close(a, b, f"state {name}")
        close(off_a, off_b, "offsets")
        close(tare_a.zero, tare_b.zero, "the F/T's zero")


@pytest.mark.parametrize("measured", [True, False], ids=["measured", "reference"])
@pytest.mark.parametrize("touched", [True, False], ids=["gripped", "untouched"])
def test_tick_front_conditions_the_ft_reading_at_the_measured_rotation(
    ctrl: Controller, measured: bool, touched: bool
) -> None:
    """The hand's wrench is :func:`conditioned_ft` of the reading: the grip's weight at {E}'s measured rotation
    ({H} is parallel to {E}; the reference's without a measurement), the zero stepped in place only when
    nobody touches the grip; ΔF (eq 19) is taken of it."""
    assert ctrl.rcm is not None and ctrl.ref is not None
    rng, p, n = np.random.default_rng(41), ctrl.params, ctrl.ref.q.shape[0]
    assert p.grip_mass > 0.0 and p.zero_gain > 0.0  # the defaults: both on
    q, dq = ctrl.ref.q + rng.uniform(-0.2, 0.2, n), np.zeros(n)
    R_m, p_m = (a.copy() for a in ctrl.model.placement_E_into(q + rng.normal(0.0, 0.05, n)))
    tactile = np.full(64, 60.0 if touched else 0.0)
    force, torque, ext = np.array([0.3, -0.2, 0.5]), np.array([0.01, 0.0, -0.02]), rng.uniform(-5.0, 5.0, 3)
    tare = FtTare.at(ctrl.model.kinematics(ctrl.ref.q, np.zeros(n)).R_H)
    tare.zero[:] = [0.1, 0.0, -0.1, 0.0, 0.01, 0.0]
    zero_before = tare.zero.copy()
    out = tc.tick_front(ctrl.model.terms(q, dq), copied(ctrl.rcm.state), ctrl.rcm.params, ext, True,
                        np.zeros(4), R_m, p_m, measured, force, torque, True, tactile, True, tare, p)
    kin, got_force, got_torque = out[0], out[5], out[6]
    R_H = R_m if measured else kin.R_H
    want_zero = zero_before.copy()
    want = conditioned_ft(force, torque, R_H, tare.R_H0, p.grip_mass, p.grip_com, want_zero, p.zero_gain, tactile,
                          True, p.contact_threshold)
    close(np.r_[got_force, got_torque], np.r_[want[0], want[1]], "the hand's wrench")
    close(tare.zero, want_zero, "the zero, stepped alike")
    assert np.any(tare.zero != zero_before) is not touched  # stepped while untouched only
    assert np.linalg.norm(got_force - force) > 1e-3  # the weight change at a turned wrist is not nothing
    close(out[3], residual_force(kin.R_H @ got_force, ext), "ΔF of the hand's force")
