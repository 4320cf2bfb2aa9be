"""Joint limits: the safety scaling and the fraction of each limit a reference sequence uses."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import two_joint_limits

from lapwrench.robot.limits import limit_usage

DT = 1e-3


def test_scaling_touches_only_the_rate_limits() -> None:
    lim = two_joint_limits()
    half = lim.scaled(0.5)
    np.testing.assert_array_equal(half.velocity, [1.0, 2.0])
    np.testing.assert_array_equal(half.acceleration, [5.0, 10.0])
    np.testing.assert_array_equal(half.jerk, [500.0, 1000.0])
    for name in ("position_lower", "position_upper", "torque", "torque_rate"):
        np.testing.assert_array_equal(getattr(half, name), getattr(lim, name))


def test_a_held_reference_uses_nothing() -> None:
    usage = limit_usage(np.zeros((50, 2)), DT, two_joint_limits())
    assert usage == {"position_excess": 0.0, "velocity": 0.0, "acceleration": 0.0, "jerk": 0.0}


def test_a_constant_speed_ramp_uses_its_velocity_and_the_start_from_rest() -> None:
    """From rest at 0, joint 1 ramps at 1 rad/s: a quarter of its 4 rad/s; the start is one step of
    acceleration (1 rad/s in 1 ms) and jerk, as libfranka differentiates the commands."""
    t = DT * np.arange(1, 101)
    q = np.column_stack([np.zeros_like(t), t])
    usage = limit_usage(q, DT, two_joint_limits(), q_start=np.zeros(2))
    assert usage["velocity"] == pytest.approx(0.25)
    assert usage["acceleration"] == pytest.approx(1.0 / DT / 20.0)
    assert usage["jerk"] == pytest.approx(1.0 / DT**2 / 2000.0)
    assert usage["position_excess"] == 0.0


def test_leaving_the_position_range_is_a_fraction_of_the_range() -> None:
    q = np.array([[0.0, 2.4], [0.0, 2.4]])  # 0.4 rad beyond a 4 rad range
    assert limit_usage(q, DT, two_joint_limits())["position_excess"] == pytest.approx(0.1)
    q = np.array([[-1.5, 0.0]])  # 0.5 rad below a 2 rad range
    assert limit_usage(q, DT, two_joint_limits())["position_excess"] == pytest.approx(0.25)
