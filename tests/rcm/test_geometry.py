"""The RCM Jacobians and the closest point against central finite differences at random configurations."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import kinematics_at_rest, numeric_jacobian, random_configuration

from lapwrench.rcm.geometry import (
    closest_point,
    closest_point_jacobian,
    closest_point_parameter,
    lateral_rcm_jacobian,
    rcm_error,
    rcm_error_drift,
    rcm_jacobian,
)
from lapwrench.robot.model import RobotModel


def _rcm_point(model: RobotModel, q: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    kin = kinematics_at_rest(model, q)
    return kin.p_E + 0.23 * kin.d_z + 0.01 * rng.standard_normal(3)


@pytest.mark.parametrize("seed", range(5))
def test_rcm_jacobian_matches_derivative_of_eq27(any_model: RobotModel, seed: int) -> None:
    rng = np.random.default_rng(10 + seed)
    q = random_configuration(any_model, rng)
    p_R = _rcm_point(any_model, q, rng)
    J_num = numeric_jacobian(lambda x: rcm_error(kinematics_at_rest(any_model, x), p_R), q)
    kin = kinematics_at_rest(any_model, q)
    np.testing.assert_allclose(rcm_jacobian(kin, p_R), J_num, atol=1e-6)
    np.testing.assert_allclose(lateral_rcm_jacobian(kin, p_R), kin.P @ J_num, atol=1e-6)


@pytest.mark.parametrize("seed", range(5))
def test_rcm_error_drift_is_the_second_derivative_along_a_straight_joint_path(any_model: RobotModel,
                                                                              seed: int) -> None:
    """ë_R at θ̈ = 0, p̈_R = 0: e_R(q + t θ̇, p_R + t ṗ_R) differentiated twice in t (central differences),
    with the adaptive point moving too."""
    rng = np.random.default_rng(20 + seed)
    q = random_configuration(any_model, rng)
    dq, p_R_dot = rng.uniform(-1.0, 1.0, any_model.nv), rng.uniform(-0.05, 0.05, 3)
    p_R = _rcm_point(any_model, q, rng)
    h = 1e-4
    e = [rcm_error(kinematics_at_rest(any_model, q + s * h * dq), p_R + s * h * p_R_dot) for s in (1.0, 0.0, -1.0)]
    want = (e[0] - 2.0 * e[1] + e[2]) / h**2
    got = rcm_error_drift(any_model.kinematics(q, dq), p_R, p_R_dot)
    np.testing.assert_allclose(got, want, atol=1e-5 * max(1.0, float(np.abs(want).max())))
    assert np.abs(want).max() > 1e-3  # a path that bends: the test can tell a wrong drift from zero


@pytest.mark.parametrize("seed", range(5))
def test_closest_point_jacobian(any_model: RobotModel, seed: int) -> None:
    rng = np.random.default_rng(20 + seed)
    q = random_configuration(any_model, rng)
    p_R = _rcm_point(any_model, q, rng)
    kin = kinematics_at_rest(any_model, q)
    s_star = closest_point_parameter(kin, p_R, any_model.length)
    _, o_G = closest_point(kin, s_star, any_model.length)
    J_G = closest_point_jacobian(kin, o_G)
    # s* frozen: G is the body-fixed point at s* L along the shaft
    J_v = numeric_jacobian(lambda x: closest_point(kinematics_at_rest(any_model, x), s_star, any_model.length)[0], q)
    np.testing.assert_allclose(J_G[3:], J_v, atol=1e-6)
    np.testing.assert_allclose(J_G[:3], kin.J_E[:3])


def test_lateral_rcm_jacobian_has_axis_null_direction(panda: RobotModel) -> None:
    rng = np.random.default_rng(3)
    q = random_configuration(panda, rng)
    kin = kinematics_at_rest(panda, q)
    J = lateral_rcm_jacobian(kin, _rcm_point(panda, q, rng))
    np.testing.assert_allclose(kin.d_z @ J, 0.0, atol=1e-12)
    assert np.linalg.matrix_rank(J, tol=1e-8) == 2


def test_closest_point_is_clamped_to_the_shaft(panda: RobotModel) -> None:
    kin = kinematics_at_rest(panda, np.array([0.0, 0.2, 0.0, -2.0, 0.0, 2.2, 0.785]))
    beyond = kin.p_E + 2.0 * panda.length * kin.d_z
    behind = kin.p_E - 0.5 * kin.d_z
    assert closest_point_parameter(kin, beyond, panda.length) == 1.0
    assert closest_point_parameter(kin, behind, panda.length) == 0.0
    assert closest_point_parameter(kin, kin.p_E + 0.1 * kin.d_z, panda.length) == pytest.approx(0.1 / 0.29)
