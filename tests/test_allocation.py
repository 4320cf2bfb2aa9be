"""Task-priority fusion (eq 2-4): null-space projection and the printed inverse."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_configuration

from lapwrench.allocation import (
    nullspace_projector,
    nullspace_torque,
    nullspace_wrench,
    regularised_inverse,
    task_priority_torque,
    weighted_pseudo_inverse,
)
from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.rcm.geometry import lateral_rcm_jacobian, rcm_jacobian
from lapwrench.robot.model import Kinematics, RobotModel
from lapwrench.sensors import SensorFrame
from lapwrench.spatial import Wrench


@pytest.mark.parametrize("seed", range(8))
@pytest.mark.parametrize("task", ["lateral", "printed"])
def test_nullspace_torque_gives_no_rcm_task_acceleration(any_model: RobotModel, seed: int, task: str) -> None:
    rng = np.random.default_rng(seed)
    q = random_configuration(any_model, rng)
    kin = any_model.kinematics(q, rng.standard_normal(7))
    # printed eq (4) needs an invertible J M^-1 J^T: keep p_R 1 cm off the axis
    p_R = kin.p_E + 0.23 * kin.d_z + 0.01 * kin.R_E[:, 0]
    J = lateral_rcm_jacobian(kin, p_R) if task == "lateral" else rcm_jacobian(kin, p_R)
    Minv = np.linalg.inv(kin.M)
    J_pinv = weighted_pseudo_inverse(J, Minv, kin.d_z if task == "lateral" else None)
    N = nullspace_projector(J, J_pinv)
    tau_n = 10.0 * rng.standard_normal(7)
    acc = J @ Minv @ N.T @ tau_n
    assert np.linalg.norm(acc) < 1e-9 * max(1.0, np.linalg.norm(J @ Minv @ tau_n))
    # and the task torque is untouched by the projection
    F_r = rng.standard_normal(3)
    np.testing.assert_allclose(task_priority_torque(J, F_r, N, np.zeros(7)), J.T @ F_r)


def test_projection_is_not_trivial(panda: RobotModel) -> None:
    rng = np.random.default_rng(1)
    q = random_configuration(panda, rng)
    kin = panda.kinematics(q, np.zeros(7))
    J = lateral_rcm_jacobian(kin, kin.p_E + 0.23 * kin.d_z)
    N = nullspace_projector(J, weighted_pseudo_inverse(J, np.linalg.inv(kin.M), kin.d_z))
    assert np.linalg.matrix_rank(N, tol=1e-8) == 5  # 7 joints minus the 2 lateral RCM constraints


def test_nullspace_wrench_sums_wrenches_about_the_closest_point() -> None:
    p_G = np.array([0.1, 0.0, 0.2])
    w1 = Wrench(np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.1, 0.0, 0.3]))
    w2 = Wrench(np.array([0.0, 0.0, 0.5]), np.zeros(3), np.zeros(3))
    W = nullspace_wrench(np.stack([w1.vector, w2.vector]), np.stack([w1.point, w2.point]), p_G)
    np.testing.assert_allclose(W, [0.0, 0.1, 0.5, 1.0, 0.0, 0.0], atol=1e-12)
    J_G = np.arange(42.0).reshape(6, 7)
    np.testing.assert_allclose(nullspace_torque(J_G, W), J_G.T @ W)


# -- eq (4) for the printed RCM task at e_R = 0 (issue 9, point 6) ---------------------------------


def _printed_at(kin: Kinematics, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """The printed J_R (eq 28) with p_R on the axis (offset 0) or ``offset`` m beside it."""
    p_R = kin.p_E + 0.232 * kin.d_z + offset * kin.R_E[:, 0]
    return rcm_jacobian(kin, p_R), lateral_rcm_jacobian(kin, p_R)


@pytest.mark.parametrize("seed", range(6))
def test_printed_inverse_at_zero_rcm_error_is_the_lateral_pseudo_inverse(any_model: RobotModel, seed: int) -> None:
    rng = np.random.default_rng(seed)
    kin = any_model.kinematics(random_configuration(any_model, rng), np.zeros(7))
    Minv = np.linalg.inv(kin.M)
    J, J_lat = _printed_at(kin, 0.0)
    A = J @ Minv @ J.T
    eig = np.linalg.eigvalsh(A)
    assert abs(eig[0]) < 1e-14 * eig[-1]  # J_R M⁻¹ J_Rᵀ is singular: the printed inverse does not exist
    J_pinv = weighted_pseudo_inverse(J, Minv)
    assert np.all(np.isfinite(J_pinv))
    N = nullspace_projector(J, J_pinv)
    N_lat = nullspace_projector(J_lat, weighted_pseudo_inverse(J_lat, Minv, kin.d_z))
    # at e_R = 0 eq (28) is the lateral Jacobian plus a zero d_z row: the same exact projector
    np.testing.assert_allclose(N, N_lat, atol=1e-9)
    np.testing.assert_allclose(N @ N, N, atol=1e-9)
    tau_n = 10.0 * rng.standard_normal(7)
    assert np.linalg.norm(J @ Minv @ N.T @ tau_n) < 1e-9 * np.linalg.norm(tau_n)


@pytest.mark.parametrize("offset", [1e-2, 1e-3, 3e-5])
def test_printed_inverse_is_the_printed_formula_when_well_conditioned(panda: RobotModel, offset: float) -> None:
    kin = panda.kinematics(random_configuration(panda, np.random.default_rng(3)), np.zeros(7))
    Minv = np.linalg.inv(kin.M)
    J, _ = _printed_at(kin, offset)
    printed = Minv @ J.T @ np.linalg.inv(J @ Minv @ J.T)
    # the same formula, compiled: equal up to the order of the floating-point operations
    atol = 1e-9 * np.abs(printed).max()
    np.testing.assert_allclose(weighted_pseudo_inverse(J, Minv), printed, rtol=1e-9, atol=atol)


def test_regularised_inverse_is_continuous_and_zero_on_the_null_space() -> None:
    U = np.linalg.qr(np.random.default_rng(0).standard_normal((3, 3)))[0]

    def inv_of(lam_min: float) -> np.ndarray:
        return regularised_inverse((U * [lam_min, 1.0, 2.0]) @ U.T, rcond=1e-6)

    u = U[:, 0]
    delta = 2e-6  # rcond x the largest eigenvalue
    assert abs(u @ inv_of(0.0) @ u) < 1e-6 / delta  # only the rounding of the zero eigenvalue is left
    assert u @ inv_of(delta * (1 + 1e-9)) @ u == pytest.approx(1 / delta, rel=1e-6)
    assert u @ inv_of(delta * (1 - 1e-9)) @ u == pytest.approx(1 / delta, rel=1e-6)
    assert u @ inv_of(0.5 * delta) @ u == pytest.approx(0.5 / delta, rel=1e-6)  # λ / δ² below δ
    np.testing.assert_allclose(inv_of(0.5) @ ((U * [0.5, 1.0, 2.0]) @ U.T), np.eye(3), atol=1e-12)
    np.testing.assert_array_equal(regularised_inverse(np.zeros((3, 3))), np.zeros((3, 3)))


def test_printed_rcm_task_runs_from_300_random_start_poses(panda: RobotModel) -> None:
    """Issue 9: the first ticks after reset used to raise LinAlgError (p_R starts on the axis, e_R = 0)."""
    ctrl = Controller(load().replace(motion={"rcm_task": "printed"}), panda)
    rng = np.random.default_rng(9)
    for _ in range(300):
        ctrl.reset(random_configuration(panda, rng))
        for k in range(4):
            res = ctrl.tick(SensorFrame(k * ctrl.dt))
            assert np.all(np.isfinite(res.q_ref)) and np.all(np.isfinite(res.dq_ref)) and np.all(np.isfinite(res.tau))
        assert not any("non-finite" in e.message for e in ctrl.events)
