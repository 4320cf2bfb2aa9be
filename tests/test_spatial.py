"""Spatial algebra: the cross-product matrix, the wrench transform (eq 37-39) and the Wrench value."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.spatial import Wrench, skew, wrench_transform


@pytest.mark.parametrize("seed", range(5))
def test_wrench_transform_preserves_moment_about_any_point(seed: int) -> None:
    rng = np.random.default_rng(seed)
    p_H, p_G, p_any = rng.standard_normal((3, 3))
    M, F = rng.standard_normal((2, 3))
    W_G = wrench_transform(p_H, p_G) @ np.concatenate([M, F])
    np.testing.assert_allclose(W_G[3:], F)
    # the moment about any point is the same whichever point the wrench was taken about
    np.testing.assert_allclose(W_G[:3] + np.cross(p_G - p_any, F), M + np.cross(p_H - p_any, F), atol=1e-12)


def test_skew_is_the_cross_product_matrix() -> None:
    rng = np.random.default_rng(7)
    for v, w in rng.standard_normal((10, 2, 3)):
        S = skew(v)
        np.testing.assert_allclose(S @ w, np.cross(v, w), atol=1e-12)
        np.testing.assert_array_equal(S, -S.T)


def test_a_wrench_is_moment_then_force_and_moves_its_moment_point() -> None:
    w = Wrench(np.array([0.0, 0.0, 0.5]), np.array([2.0, 0.0, 0.0]), np.zeros(3))
    np.testing.assert_array_equal(w.vector, [0.0, 0.0, 0.5, 2.0, 0.0, 0.0])  # [moment; force]
    # about a point 1 m up the y axis: the force's lever arm adds (0 - p) x F = (0, -1, 0) x (2, 0, 0)
    np.testing.assert_allclose(w.about(np.array([0.0, 1.0, 0.0])), [0.0, 0.0, 2.5, 2.0, 0.0, 0.0])
    np.testing.assert_allclose(w.about(w.point), w.vector)


def test_the_zero_wrench_keeps_its_point() -> None:
    z = Wrench.zero([0.1, 0.2, 0.3])
    assert not z.vector.any()
    np.testing.assert_array_equal(z.point, [0.1, 0.2, 0.3])
    assert z.point.dtype == np.float64
