"""The interaction wrench (eq 5-7)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from lapwrench.wrenches.interaction import grip_gain, interaction_wrench, surgeon_wrench


def test_grip_gain_is_zero_at_k_min_contacts_and_switches_on_above() -> None:
    values = np.zeros(64)
    values[:3] = 200.0
    assert grip_gain(values, 2000.0, 3) == (0.0, 3)
    values[3] = 200.0
    delta, n_c = grip_gain(values, 2000.0, 3)
    assert n_c == 4
    assert delta == pytest.approx(800.0 / 2000.0)


def test_grip_gain_counts_only_elements_above_the_contact_threshold() -> None:
    values = np.full(64, 2.0)
    assert grip_gain(values, 2000.0, 3, contact_threshold=5.0) == (0.0, 0)
    assert grip_gain(values, 2000.0, 3)[1] == 64


def test_full_grip_delta_range() -> None:
    assert grip_gain(np.full(64, 255.0), 2000.0, 3)[0] == pytest.approx(64 * 255 / 2000)


def test_interaction_wrench_keeps_forces_and_axial_torque_only() -> None:
    R_H = pin.rpy.rpyToMatrix(0.3, -0.2, 1.0)
    F = np.array([1.0, -2.0, 3.0])
    M = np.array([0.5, 0.7, -0.4])
    M_s, F_s = surgeon_wrench(F, M, R_H)
    np.testing.assert_allclose(F_s, R_H @ F)
    np.testing.assert_allclose(M_s, R_H @ M)
    M_h, F_h = interaction_wrench(F, M, R_H, 2.0)
    np.testing.assert_allclose(F_h, 2.0 * R_H @ F)
    np.testing.assert_allclose(M_h, 2.0 * -0.4 * R_H[:, 2])
    M0, F0 = interaction_wrench(F, M, R_H, 0.0)
    assert not np.any(M0) and not np.any(F0)
