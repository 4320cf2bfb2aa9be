"""The F/T's zero kept while nobody touches the grip (lapwrench.wrenches.ft_zero)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from lapwrench.wrenches.ft_zero import (
    BAND_FORCE,
    BAND_TORQUE,
    MAX_FORCE,
    MAX_TORQUE,
    conditioned_ft,
    untouched,
    zero_step,
)
from lapwrench.wrenches.grip_weight import without_grip_weight


def test_untouched_needs_a_tactile_reading_with_no_element_above_the_threshold() -> None:
    values = np.zeros(64)
    assert untouched(values, True, 0.0)
    assert not untouched(values, False, 0.0)  # no reading: nobody can tell
    values[17] = 1.0
    assert not untouched(values, True, 0.0)
    assert untouched(values, True, 1.0)  # at the threshold is no contact


def test_the_zero_follows_a_steady_bias_with_its_time_constant() -> None:
    zero, F, T = np.zeros(6), np.array([0.3, -0.2, 0.1]), np.array([0.01, 0.0, -0.02])
    gain = 1e-3 / 2.0  # 1 kHz, T = 2 s
    for _ in range(2000):  # one time constant
        assert zero_step(zero, F, T, gain)
    np.testing.assert_allclose(zero[:3], F * (1 - np.exp(-1.0)), rtol=1e-3)
    np.testing.assert_allclose(zero[3:], T * (1 - np.exp(-1.0)), rtol=1e-3)
    for _ in range(20000):
        zero_step(zero, F, T, gain)
    np.testing.assert_allclose(zero, np.r_[F, T], atol=1e-5)  # e^-11 of the way left


@pytest.mark.parametrize(
    "force, torque", [([BAND_FORCE * 1.01, 0, 0], [0, 0, 0]), ([0, 0, 0], [0, 0, BAND_TORQUE * 1.01])]
)
def test_a_reading_outside_the_band_is_not_bias(force: list[float], torque: list[float]) -> None:
    """A push the tactile array missed is far from the zero: it never enters it."""
    zero = np.zeros(6)
    assert not zero_step(zero, np.array(force, float), np.array(torque, float), 0.5)
    assert np.all(zero == 0.0)


def test_the_zero_stays_within_its_bound_of_the_tare() -> None:
    """A reading that creeps away slowly (inside the band each step) drags the zero no further than the bound."""
    zero = np.zeros(6)
    F, T = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.04, 0.0])
    for k in range(100_000):
        zero_step(zero, F * (1 + k * 1e-4), T * (1 + k * 1e-4), 0.5)
    assert np.linalg.norm(zero[:3]) == pytest.approx(MAX_FORCE)
    assert np.linalg.norm(zero[3:]) == pytest.approx(MAX_TORQUE)


def test_conditioning_takes_off_the_weight_then_the_zero_and_steps_it_only_untouched() -> None:
    R0, R = pin.rpy.rpyToMatrix(0.0, np.pi, 0.0), pin.rpy.rpyToMatrix(0.2, np.pi - 0.3, 0.0)
    com = np.array([0.0, 0.0, 0.01])
    F, T = np.array([0.5, 0.1, -0.2]), np.array([0.0, 0.01, 0.0])
    gripped, free = np.full(64, 100.0), np.zeros(64)
    zero = np.array([0.1, 0.0, 0.0, 0.0, 0.0, 0.001])
    f, t = conditioned_ft(F, T, R, R0, 0.1, com, zero, 0.01, gripped, True, 0.0)
    w_F, w_T = without_grip_weight(F, T, R, R0, 0.1, com)
    np.testing.assert_allclose(f, w_F - [0.1, 0, 0], atol=1e-15)  # gripped: the zero holds and is taken off
    np.testing.assert_allclose(t, w_T - [0, 0, 0.001], atol=1e-15)
    assert zero[0] == 0.1
    conditioned_ft(F, T, R, R0, 0.1, com, zero, 0.01, free, True, 0.0)
    np.testing.assert_allclose(zero[:3], np.array([0.1, 0, 0]) + 0.01 * (w_F - [0.1, 0, 0]), atol=1e-15)
    before = zero.copy()
    f, _ = conditioned_ft(F, T, R, R0, 0.0, com, zero, 0.0, free, True, 0.0)  # no grip mass, no zeroing
    np.testing.assert_array_equal(zero, before)
    np.testing.assert_allclose(f, F - before[:3], atol=1e-15)
