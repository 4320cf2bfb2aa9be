"""lapwrench.wrenches.rcm: eq (13)-(14), the RCM wrench of the task space."""

from __future__ import annotations

import numpy as np

from lapwrench.config import load
from lapwrench.rcm.geometry import TaskGeometry
from lapwrench.wrenches.rcm import RcmCue, rcm_force


def test_eq_14_is_a_spring_and_a_damper_on_the_rcm_error() -> None:
    e, de = np.array([1e-3, -2e-3, 0.0]), np.array([0.01, 0.0, 0.0])
    np.testing.assert_allclose(rcm_force(e, de, 300.0, 20.0), -300.0 * e - 20.0 * de)
    np.testing.assert_allclose(rcm_force(np.zeros(3), np.zeros(3), 300.0, 20.0), 0.0)


def test_the_cue_is_a_pure_force_at_p_R_including_the_measured_offset() -> None:
    cfg = load()
    cue = RcmCue("rcm", cfg.rcm, cfg)
    z = np.zeros(3)
    geo = TaskGeometry(np.array([0.4, 0.0, 0.2]), z, np.array([1e-3, 0.0, 0.0]), z, np.zeros((3, 7)), 0.5,
                       z, z, np.zeros((6, 7)), np.array([0.0, 2e-3, 0.0]))

    class Ctx:
        geometry = geo

    w = cue.compute(Ctx())  # type: ignore[arg-type]
    assert cue.priority == "task" and cue.fused
    np.testing.assert_allclose(w.moment, 0.0)
    np.testing.assert_allclose(w.force, -cfg.rcm.Kp * np.array([1e-3, 2e-3, 0.0]))
    np.testing.assert_allclose(w.point, geo.p_R)
