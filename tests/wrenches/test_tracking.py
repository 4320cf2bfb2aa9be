"""The virtual tracking wrench (eq 8-12)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from lapwrench.config import load
from lapwrench.wrenches.tracking import (
    TrackingParams,
    pixel_distance,
    tracking_direction,
    unit_depth_ray,
    virtual_force,
)

CFG = load()
CAM = CFG.camera
PARAMS = TrackingParams.from_config(CAM, CFG.tracking)


@pytest.mark.parametrize("seed", range(10))
def test_direction_is_perpendicular_to_the_ray(seed: int) -> None:
    rng = np.random.default_rng(seed)
    R_C = pin.exp3(rng.uniform(-3, 3, 3))
    u, v = rng.uniform(0, 640), rng.uniform(0, 480)
    ray = unit_depth_ray(u, v, PARAMS, R_C)
    V = tracking_direction(ray, R_C[:, 2])
    assert np.linalg.norm(V) == pytest.approx(1.0)
    assert abs(V @ ray) < 1e-12
    # its image-plane part points from the principal point toward the instrument
    lateral = R_C.T @ V
    assert lateral[0] * (u - CAM.u0) > 0 and lateral[1] * (v - CAM.v0) > 0


def test_image_plane_variant_has_no_axial_component() -> None:
    R_C = np.eye(3)
    V = tracking_direction(unit_depth_ray(500.0, 100.0, PARAMS, R_C), R_C[:, 2], "image_plane")
    assert V[2] == 0.0 and np.linalg.norm(V) == pytest.approx(1.0)


def test_ray_on_the_principal_point_gives_no_direction() -> None:
    assert not np.any(tracking_direction(np.array([0.0, 0.0, 1.0]), np.array([0.0, 0.0, 1.0])))


def test_pixel_distance_eq9() -> None:
    assert pixel_distance(CAM.u0 + 3.0, CAM.v0 + 4.0, CAM.u0, CAM.v0) == pytest.approx(5.0)


def test_virtual_force_is_zero_without_instruments_or_inside_the_dead_zone() -> None:
    R_C = np.eye(3)
    assert not np.any(virtual_force(np.zeros((0, 2)), PARAMS, R_C))
    inside = np.array([[CAM.u0 + 30.0, CAM.v0 + 30.0]])
    assert not np.any(virtual_force(inside, PARAMS, R_C))


def test_virtual_force_sums_instruments_and_saturates() -> None:
    R_C = np.eye(3)
    far_right = np.array([[CAM.u0 + 300.0, CAM.v0]])
    far_left = np.array([[CAM.u0 - 300.0, CAM.v0]])
    F_r = virtual_force(far_right, PARAMS, R_C)
    assert np.linalg.norm(F_r) == pytest.approx(CFG.tracking.F_max)
    printed = CFG.replace(tracking={"direction": "printed"}).tracking
    both = virtual_force(np.vstack([far_right, far_left]), TrackingParams.from_config(CAM, printed), R_C)
    assert abs(both[0]) < 1e-9  # lateral parts cancel, the printed retraction parts add
    assert both[2] < 0


@pytest.mark.parametrize("n", [2, 3, 100, 1000])
def test_the_summed_force_is_capped_whatever_the_number_of_detections(n: int) -> None:
    """Eq 8 sums over the detections: without the cap, 100 boxes at one corner asked 1000 N."""
    corner = np.tile([[CAM.width - 1.0, CAM.height - 1.0]], (n, 1))
    F = virtual_force(corner, PARAMS, np.eye(3))
    single = virtual_force(corner[:1], PARAMS, np.eye(3))
    expected = min(n * CFG.tracking.F_max, CFG.tracking.F_sum_max)
    assert np.linalg.norm(F) == pytest.approx(expected)
    np.testing.assert_allclose(F / np.linalg.norm(F), single / np.linalg.norm(single))  # direction kept


def test_the_cap_must_let_one_instrument_reach_F_max() -> None:
    from lapwrench.config import ConfigError

    with pytest.raises(ConfigError, match="F_sum_max"):
        CFG.replace(tracking={"F_sum_max": 5.0})
