"""The reference shaper keeps every request inside the joint limits."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.motion.reference_shaper import ReferenceShaper, ReferenceState
from lapwrench.robot.limits import franka_limits, limit_usage
from lapwrench.robot.model import RobotModel
from lapwrench.virtual import DEFAULT_Q0


@pytest.mark.parametrize("kind", ["panda", "fr3"])
def test_shaper_keeps_wild_requests_inside_every_limit(kind: str) -> None:
    model = RobotModel(kind)
    shaper = ReferenceShaper(model.limits, 1e-3, 0.9, 0.05)
    rng = np.random.default_rng(0)
    state = ReferenceState(DEFAULT_Q0.copy(), np.zeros(7), np.zeros(7))
    qs = []
    for k in range(4000):
        wish = rng.choice([-1e3, 1e3], size=7) if (k // 400) % 2 else 50.0 * rng.standard_normal(7)
        if k == 1234:
            wish[2] = np.nan
        state = shaper.step(state, wish)
        qs.append(state.q)
    usage = limit_usage(np.array(qs), 1e-3, model.limits, DEFAULT_Q0)
    assert usage["position_excess"] == 0.0
    assert usage["velocity"] <= 0.9 + 1e-9
    assert usage["acceleration"] <= 0.9 + 1e-9
    assert usage["jerk"] <= 0.9 + 1e-9
    assert np.all(np.isfinite(qs))


def test_shaper_stops_before_the_position_limit() -> None:
    lim = franka_limits("panda")
    shaper = ReferenceShaper(lim, 1e-3, 0.9, 0.05)
    state = ReferenceState(DEFAULT_Q0.copy(), np.zeros(7), np.zeros(7))
    for _ in range(5000):
        state = shaper.step(state, np.full(7, 10.0))
    assert np.all(state.q <= lim.position_upper - 0.05 + 1e-4)  # overshoot into the margin is tiny
    assert np.max(np.abs(state.dq)) < 0.05


def test_shaper_passes_feasible_requests_unchanged() -> None:
    shaper = ReferenceShaper(franka_limits("panda"), 1e-3, 0.9, 0.05)
    state = ReferenceState(DEFAULT_Q0.copy(), np.zeros(7), np.zeros(7))
    nxt = shaper.step(state, np.full(7, 1e-3))
    np.testing.assert_allclose(nxt.dq, 1e-3)
    np.testing.assert_allclose(nxt.q, DEFAULT_Q0 + 1e-6)
