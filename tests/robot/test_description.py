"""The scope description: parallel frames by default, the 30° oblique option and tracking with it."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.robot.description import FRAME_C, FRAME_E, ScopeGeometry
from lapwrench.robot.model import RobotModel
from lapwrench.virtual import DEFAULT_Q0, project_points, run_virtual


def test_parallel_frames_by_default() -> None:
    m = RobotModel("panda")
    kin = m.kinematics(DEFAULT_Q0, np.zeros(7))
    np.testing.assert_allclose(kin.R_C, kin.R_E, atol=1e-12)
    np.testing.assert_allclose(kin.R_H, kin.R_E, atol=1e-12)
    np.testing.assert_allclose(kin.p_C, kin.p_E + 0.29 * kin.d_z, atol=1e-12)


def test_oblique_camera_looks_30_degrees_off_the_shaft() -> None:
    m = RobotModel("panda", ScopeGeometry(oblique_angle_deg=30.0))
    kin = m.kinematics(DEFAULT_Q0, np.zeros(7))
    angle = math.degrees(math.acos(kin.R_C[:, 2] @ kin.d_z))
    assert angle == pytest.approx(30.0, abs=1e-6)  # URDF text keeps 9 digits
    np.testing.assert_allclose(kin.R_C[:, 0], kin.R_E[:, 0], atol=1e-12)  # tilted about x_E
    np.testing.assert_allclose(kin.p_C, kin.p_E + 0.29 * kin.d_z, atol=1e-12)
    assert m.frame_pose(DEFAULT_Q0, FRAME_C).translation == pytest.approx(
        m.frame_pose(DEFAULT_Q0, FRAME_E).translation + 0.29 * kin.d_z
    )


def test_oblique_scope_tracks_in_its_own_camera_frame() -> None:
    cfg = load().replace(scope={"oblique_angle_deg": 30.0})
    ctrl = Controller(cfg)
    kin = ctrl.model.kinematics(DEFAULT_Q0, np.zeros(7))
    depth = 0.07
    point = kin.p_C + kin.R_C @ np.array([150.0 / cfg.camera.fx * depth, 0.0, depth])
    uv, vis = project_points(point[None], kin.p_C, kin.R_C, cfg.camera)
    assert vis[0] and math.hypot(uv[0, 0] - cfg.camera.u0, uv[0, 1] - cfg.camera.v0) == pytest.approx(150.0, abs=0.5)
    _, log = run_virtual(cfg, 3.0, instruments=lambda t: point[None], controller=ctrl)
    d = [math.hypot(p[0, 0] - cfg.camera.u0, p[0, 1] - cfg.camera.v0) for p in log.pixels if len(p)]
    assert d[-1] < cfg.tracking.epsilon1
    assert max(r.rcm_error for r in log.results) < 5e-4
