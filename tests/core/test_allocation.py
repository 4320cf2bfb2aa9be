"""Task-priority fusion (eq 2-4) and the wrench transform (eq 37-39)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_configuration

from lapwrench.allocation import (
    nullspace_projector,
    nullspace_torque,
    nullspace_wrench,
    task_priority_torque,
    weighted_pseudo_inverse,
)
from lapwrench.rcm.geometry import lateral_rcm_jacobian, rcm_jacobian
from lapwrench.robot.model import RobotModel
from lapwrench.spatial import Wrench, wrench_transform


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


@pytest.mark.parametrize("seed", range(5))
def test_wrench_transform_preserves_moment_about_any_point(seed: int) -> None:
    rng = np.random.default_rng(seed)
    p_H, p_G, p_any = rng.standard_normal((3, 3))
    M, F = rng.standard_normal((2, 3))
    W_G = wrench_transform(p_H, p_G) @ np.concatenate([M, F])
    np.testing.assert_allclose(W_G[3:], F)
    # the moment about any point is the same whichever point the wrench was taken about
    np.testing.assert_allclose(W_G[:3] + np.cross(p_G - p_any, F), M + np.cross(p_H - p_any, F), atol=1e-12)


def test_nullspace_wrench_sums_wrenches_about_the_closest_point() -> None:
    p_G = np.array([0.1, 0.0, 0.2])
    w1 = Wrench(np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([0.1, 0.0, 0.3]))
    w2 = Wrench(np.array([0.0, 0.0, 0.5]), np.zeros(3), np.zeros(3))
    W = nullspace_wrench([w1, w2], p_G)
    np.testing.assert_allclose(W, [0.0, 0.1, 0.5, 1.0, 0.0, 0.0], atol=1e-12)
    J_G = np.arange(42.0).reshape(6, 7)
    np.testing.assert_allclose(nullspace_torque(J_G, W), J_G.T @ W)
