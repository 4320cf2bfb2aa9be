"""The tick's parameters gathered from the configuration and the arm's limits."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import two_joint_limits

from lapwrench.config import load
from lapwrench.tick_params import TickParams

LIMITS = two_joint_limits()  # a made-up two-joint arm: the parameters follow the arm's joint count


def test_rate_limits_are_scaled_and_the_position_band_keeps_the_margin() -> None:
    cfg = load().replace(robot={"limit_fraction": 0.5, "position_margin": 0.1})
    p = TickParams.from_config(cfg, LIMITS)
    np.testing.assert_allclose(p.v_max, [1.0, 2.0])
    np.testing.assert_allclose(p.a_max, [5.0, 10.0])
    np.testing.assert_allclose(p.j_max, [500.0, 1000.0])
    np.testing.assert_allclose(p.q_lo, [-0.9, -1.9])
    np.testing.assert_allclose(p.q_hi, [0.9, 1.9])


def test_the_damping_matrices_are_eq40_guided_and_unguided() -> None:
    cfg = load().replace(viscous={"k_t": 1.5, "k_t_unguided": 7.0, "k_f": 30.0})
    p = TickParams.from_config(cfg, LIMITS)
    np.testing.assert_array_equal(p.D_guided, np.diag([1.5] * 3 + [30.0] * 3))
    np.testing.assert_array_equal(p.D_unguided, np.diag([7.0] * 3 + [30.0] * 3))


def test_scalars_come_from_their_sections() -> None:
    cfg = load()
    p = TickParams.from_config(cfg, LIMITS)
    assert p.dt == cfg.robot.dt and p.length == cfg.scope.length
    assert (p.Kp, p.Kd) == (cfg.rcm.Kp, cfg.rcm.Kd)
    assert p.lateral == (cfg.motion.rcm_task == "lateral")
    assert p.k_min == cfg.interaction.k_min and isinstance(p.k_min, int)
    assert p.feedback_cap == pytest.approx(2.0 * cfg.safety.max_rcm_error)
    assert 0.0 < p.feedback_gain <= 1.0
    assert p.envelope_enabled == cfg.envelope.enabled


def test_every_array_is_float64_for_the_compiled_tick() -> None:
    p = TickParams.from_config(load(), LIMITS)
    arrays = [v for v in p if isinstance(v, np.ndarray)]
    assert len(arrays) >= 7
    assert all(a.dtype == np.float64 for a in arrays)
