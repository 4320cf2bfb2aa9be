"""lapwrench.hardware.grip_fit: the grip's mass and centre of mass from untouched F/T readings."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from lapwrench.hardware.grip_fit import (
    MIN_SAMPLES,
    GripFitError,
    fit_grip,
    gravity_in_H,
    skew_rows,
    tilt_span_deg,
)
from lapwrench.wrenches.grip_weight import GRAVITY_B, grip_weight_change

MASS, COM = 0.1, np.array([0.003, -0.002, 0.01])
F_BIAS, T_BIAS = np.array([0.2, -0.1, 0.3]), np.array([0.005, 0.0, -0.004])
F_SIGMA, T_SIGMA = 0.1, 0.005  # the simulated HEX-E's noise


def readings(
    R: np.ndarray, mass: float = MASS, com: np.ndarray = COM, seed: int = 0, noise: float = 1.0
) -> tuple[np.ndarray, np.ndarray]:
    """F/T readings of the untouched grip at rotations ``R`` (the model of lapwrench.wrenches.grip_weight),
    with the bias and ``noise`` times the sensor's noise."""
    rng = np.random.default_rng(seed)
    u = gravity_in_H(R)
    F = F_BIAS + mass * u + noise * F_SIGMA * rng.standard_normal(u.shape)
    T = T_BIAS + np.cross(com, mass * u) + noise * T_SIGMA * rng.standard_normal(u.shape)
    return F, T


def tilted(n: int, max_deg: float, seed: int = 0) -> np.ndarray:
    """``n`` rotations of {H}: the scope pointing down, tilted up to ``max_deg`` in random directions and
    turned about its axis at random."""
    rng = np.random.default_rng(seed)
    down = Rotation.from_euler("x", 180, degrees=True)
    axis = np.c_[rng.standard_normal((n, 2)), np.zeros(n)]
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    tilt = Rotation.from_rotvec(axis * np.radians(rng.uniform(0, max_deg, n))[:, None])
    roll = Rotation.from_euler("z", rng.uniform(-180, 180, (n, 1)), degrees=True)
    return (tilt * down * roll).as_matrix()


def test_gravity_in_H_is_R_transpose_g_and_matches_the_controllers_grip_model() -> None:
    R = Rotation.random(5, random_state=1).as_matrix()
    u = gravity_in_H(R)
    assert np.allclose(u, [r.T @ GRAVITY_B for r in R])
    # the controller's model: the change of the weight between two rotations is m (u - u0), c × that
    dF, dT = grip_weight_change(np.asfortranarray(R[1]), np.asfortranarray(R[0]), MASS, COM)
    assert np.allclose(dF, MASS * (u[1] - u[0])) and np.allclose(dT, np.cross(COM, MASS * (u[1] - u[0])))


def test_skew_rows_is_the_cross_product() -> None:
    v, w = np.random.default_rng(2).standard_normal((2, 4, 3))
    assert np.allclose(np.einsum("nij,nj->ni", skew_rows(v), w), np.cross(v, w))


def test_tilt_span_is_the_largest_angle_between_directions() -> None:
    u = np.array([[0, 0, -1.0], [math.sin(0.3), 0, -math.cos(0.3)], [0, -math.sin(0.2), -math.cos(0.2)]]) * 9.81
    # 17° and 11° from the first; between the other two, whose dot product is cos 0.3 cos 0.2, the most
    assert tilt_span_deg(u) == pytest.approx(math.degrees(math.acos(math.cos(0.3) * math.cos(0.2))), abs=1e-6)
    many = gravity_in_H(tilted(20_000, 25.0))  # subsampled: the extremes are kept
    assert 48.0 < tilt_span_deg(many) <= 50.0 + 1e-9


@settings(max_examples=30, deadline=None)
@given(
    mass=st.floats(0.02, 1.5),
    com=st.tuples(*[st.floats(-0.05, 0.05)] * 3),
    seed=st.integers(0, 2**31 - 1),
)
def test_a_known_grip_is_recovered_from_noisy_readings_at_random_rotations(
    mass: float, com: tuple[float, float, float], seed: int
) -> None:
    R = Rotation.random(2000, random_state=seed).as_matrix()
    F, T = readings(R, mass, np.array(com), seed)
    fit = fit_grip(R, F, T)
    # standard errors here: 0.25 g, and 0.014 g m / mass for the centre of mass
    assert fit.mass == pytest.approx(mass, abs=0.002)
    assert np.allclose(fit.com, com, atol=1e-4 / mass)
    assert np.allclose(fit.force_bias, F_BIAS, atol=0.02) and np.allclose(fit.torque_bias, T_BIAS, atol=1e-3)
    assert fit.force_rms == pytest.approx(math.sqrt(3) * F_SIGMA, rel=0.1)
    assert fit.torque_rms == pytest.approx(math.sqrt(3) * T_SIGMA, rel=0.1)
    assert fit.samples == 2000 and fit.tilt_span_deg > 170.0


def test_a_scope_tilted_twenty_degrees_gives_the_grip_within_its_standard_errors() -> None:
    R = tilted(5000, 20.0, seed=3)
    fit = fit_grip(R, *readings(R, seed=3))
    assert abs(fit.mass - MASS) < 4 * fit.mass_sigma and fit.mass_sigma < 0.003
    assert np.all(np.abs(fit.com - COM) < 4 * fit.com_sigma) and fit.com_sigma.max() < 1e-3
    assert 35.0 < fit.tilt_span_deg <= 40.0


def test_exact_readings_give_the_grip_exactly() -> None:
    R = tilted(200, 15.0, seed=4)
    fit = fit_grip(R, *readings(R, noise=0.0))
    assert fit.mass == pytest.approx(MASS, rel=1e-9) and np.allclose(fit.com, COM, atol=1e-9)
    assert fit.force_rms < 1e-9 and fit.torque_rms < 1e-9


def test_rows_with_nan_are_dropped() -> None:
    R = tilted(600, 20.0, seed=5)
    F, T = readings(R, seed=5)
    clean = fit_grip(R, F, T)
    R, F, T = R.copy(), F.copy(), T.copy()
    F[::7, 0], T[3::11, 2], R[5::13, 1, 1] = np.nan, np.inf, np.nan
    dirty = fit_grip(R, F, T)
    assert dirty.samples == 600 - len({*range(0, 600, 7), *range(3, 600, 11), *range(5, 600, 13)})
    assert dirty.mass == pytest.approx(clean.mass, abs=0.01) and np.allclose(dirty.com, clean.com, atol=3e-3)


def test_too_little_tilt_is_refused_with_what_to_do() -> None:
    R = tilted(3000, 4.0, seed=6)  # at most 8° between two directions
    with pytest.raises(GripFitError, match=r"turned only .*°.*tilt the scope by at least 10°"):
        fit_grip(R, *readings(R))


def test_two_resting_orientations_do_not_determine_the_centre_of_mass() -> None:
    R = np.repeat(tilted(2, 20.0, seed=7), 500, axis=0)  # gravity along one line through two points
    with pytest.raises(GripFitError, match="one direction only"):
        fit_grip(R, *readings(R))


def test_too_few_readings_are_refused() -> None:
    R = tilted(MIN_SAMPLES - 1, 30.0)
    with pytest.raises(GripFitError, match=f"only {MIN_SAMPLES - 1} usable readings"):
        fit_grip(R, *readings(R))
    R = tilted(MIN_SAMPLES + 50, 30.0)
    F, T = readings(R)
    F[:51] = np.nan
    with pytest.raises(GripFitError, match=f"only {MIN_SAMPLES - 1} usable"):
        fit_grip(R, F, T)


def test_no_grip_weight_or_a_negative_mass_is_refused() -> None:
    R = tilted(3000, 20.0, seed=8)
    with pytest.raises(GripFitError, match=r"-\d+\.\d g: the F/T does not see a grip weight"):
        fit_grip(R, *readings(R, mass=-0.05))
    with pytest.raises(GripFitError, match="grip_mass: 0"):
        fit_grip(R, *readings(R, mass=0.0, seed=9, noise=0.0))


def test_an_implausible_grip_is_refused() -> None:
    R = tilted(3000, 30.0, seed=10)
    with pytest.raises(GripFitError, match="implausible"):
        fit_grip(R, *readings(R, mass=3.0))
    with pytest.raises(GripFitError, match="implausible"):
        fit_grip(R, *readings(R, mass=0.1, com=np.array([0.0, 0.0, 0.5])))


def test_mismatched_shapes_are_a_value_error() -> None:
    R = tilted(200, 20.0)
    F, T = readings(R)
    with pytest.raises(ValueError, match="expected rotations"):
        fit_grip(R[:, :2], F, T)
    with pytest.raises(ValueError, match="expected rotations"):
        fit_grip(R, F[:-1], T)
