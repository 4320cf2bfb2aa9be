"""Closed loop on the virtual robot (run_virtual): convergence, pivoting, tracking, supervision."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from lapwrench.config import Config, load
from lapwrench.controller import Controller
from lapwrench.rcm.geometry import initial_rcm_point
from lapwrench.virtual import DEFAULT_Q0, HandScript, VirtualLog, limits_report, plot_virtual, run_virtual


def _assert_inside_limits(ctrl: Controller, log: VirtualLog) -> None:
    usage = limits_report(ctrl, log, DEFAULT_Q0)
    assert usage["position_excess"] == 0.0
    for k in ("velocity", "acceleration", "jerk"):
        assert usage[k] <= 1.0, usage
    assert all(np.all(np.isfinite(r.q_ref)) for r in log.results)


@pytest.mark.parametrize("kind", ["panda", "fr3"])
def test_starting_5mm_off_the_rcm_converges_below_0p1mm(kind: str) -> None:
    # the supervisor holds at 5 mm of measured RCM error: give this convergence test room
    cfg = load().replace(robot={"kind": kind}, safety={"max_rcm_error": 0.008})
    ctrl = Controller(cfg)
    ctrl.reset(DEFAULT_Q0)
    kin = ctrl.model.kinematics(DEFAULT_Q0, np.zeros(7))
    p_R = kin.p_E + 0.232 * kin.d_z + 0.005 * kin.R_E[:, 0]
    ctrl, log = run_virtual(cfg, 2.0, p_R=p_R, controller=ctrl)
    err = np.array([r.rcm_error for r in log.results])
    assert err[0] == pytest.approx(0.005, rel=1e-6)
    assert err[-1] < 1e-4
    assert np.max(err[1000:]) < 1e-4
    _assert_inside_limits(ctrl, log)


@pytest.mark.parametrize("task", ["lateral", "printed"])
def test_handle_force_pivots_the_scope_about_the_rcm(task: str) -> None:
    cfg = load().replace(motion={"rcm_task": task})
    hand = HandScript(force=lambda t: np.array([10.0, 0.0, 0.0]), delta=lambda t: 2.0)
    ctrl, log = run_virtual(cfg, 3.0, hand=hand)
    assert all(r.delta == pytest.approx(2.0) for r in log.results)
    assert all(r.mode == "handle" for r in log.results)
    err = np.array([r.rcm_error for r in log.results])
    assert np.max(err) < 5e-4
    # the scope pivoted: its axis turned, and the proximal end moved along the force while the tip moved against it
    (e0, t0), (e1, t1) = log.axis_points[0], log.axis_points[-1]
    a0, a1 = (t0 - e0) / np.linalg.norm(t0 - e0), (t1 - e1) / np.linalg.norm(t1 - e1)
    angle = np.degrees(np.arccos(np.clip(a0 @ a1, -1, 1)))
    assert angle > 2.0
    R_H = ctrl.model.kinematics(DEFAULT_Q0, np.zeros(7)).R_H
    push = R_H @ np.array([1.0, 0.0, 0.0])
    assert (e1 - e0) @ push > 0 and (t1 - t0) @ push < 0
    _assert_inside_limits(ctrl, log)


def test_no_grip_means_no_motion() -> None:
    cfg = load()
    hand = HandScript(force=lambda t: np.array([10.0, 0.0, 0.0]), delta=lambda t: 0.0)
    _ctrl, log = run_virtual(cfg, 0.5, hand=hand)
    assert np.max(np.abs(log.results[-1].q_ref - DEFAULT_Q0)) < 1e-9


def _instrument_at(cfg: Config, pixels: float) -> np.ndarray:
    """A fixed point on tissue 7 cm ahead of the camera, ``pixels`` right of the principal point."""
    ctrl = Controller(cfg)
    kin = ctrl.model.kinematics(DEFAULT_Q0, np.zeros(7))
    depth = 0.07
    return kin.p_C + kin.R_C @ np.array([pixels / cfg.camera.fx * depth, 0.0, depth])


@pytest.mark.parametrize(
    ("preset", "duration"),
    [({"viscous": {"k_t_unguided": 150.0, "k_f": 2.0}}, 60.0), ({}, 3.0)],
    ids=["paper-damping", "default-damping"],
)
def test_instrument_150px_off_centre_is_brought_inside_eps1(preset: dict, duration: float) -> None:
    cfg = load().replace(**preset)
    point = _instrument_at(cfg, 150.0)
    ctrl, log = run_virtual(cfg, duration, instruments=lambda t: point[None])
    d = np.array([np.hypot(*(p[0] - [cfg.camera.u0, cfg.camera.v0])) for p in log.pixels])
    assert d[0] == pytest.approx(150.0, abs=0.5)
    assert log.results[0].mode == "tracking"
    assert d[-1] < cfg.tracking.epsilon1
    assert np.max([r.rcm_error for r in log.results]) < 5e-4
    # re-centred by pivoting, not by pulling the scope out: the insertion depth barely changes
    depth = [np.linalg.norm(r.p_R - e) for r, (e, _) in zip(log.results, log.axis_points, strict=True)]
    assert np.ptp(depth) < 0.01
    _assert_inside_limits(ctrl, log)


def test_printed_direction_with_paper_damping_retracts_the_scope() -> None:
    """Why ``tracking.direction`` defaults to the image-plane reading (see tracking_direction),
    and how the envelope's depth wall stops the retraction at ``envelope.depth_min``."""
    point = None
    for enabled in (False, True):
        cfg = load().replace(
            tracking={"direction": "printed"},
            envelope={"enabled": enabled},
            viscous={"k_f": 2.0, "k_t_unguided": 150.0},  # the paper's table
        )
        point = _instrument_at(cfg, 150.0) if point is None else point
        _, log = run_virtual(cfg, 1.0, instruments=lambda t, p=point: p[None])
        depth = [np.linalg.norm(r.p_R - e) for r, (e, _) in zip(log.results, log.axis_points, strict=True)]
        tip_depth = cfg.scope.length - depth[-1]
        if not enabled:
            # the flange moved 3+ cm away from the RCM, the scope was pulled out until the supervisor,
            # watching the measured depth, held it
            assert depth[-1] - depth[0] > 0.03
            assert log.alarm is not None and "depth" in log.alarm, log.alarm
        else:
            assert log.alarm is None
            assert cfg.envelope.depth_min - 1e-4 <= tip_depth < cfg.envelope.depth_min + 0.003


def test_the_supervisor_holds_a_virtual_run_that_starts_beyond_its_rcm_bound() -> None:
    """The virtual model runs through the one control loop with the supervisor in the path."""
    cfg = load()
    ctrl = Controller(cfg)
    ctrl.reset(DEFAULT_Q0)
    kin = ctrl.model.kinematics(DEFAULT_Q0, np.zeros(7))
    p_R0 = initial_rcm_point(kin, cfg.scope.length, cfg.scope.lambda0)
    p_R = p_R0 + 0.006 * kin.R_E[:, 0]  # 6 mm off: beyond safety.max_rcm_error
    _, log = run_virtual(cfg, 1.0, p_R=p_R, controller=ctrl)
    assert log.alarm is not None and log.alarm.startswith("rcm_error"), log.alarm
    assert len(log.results) < 10


def test_the_plot_of_a_run_with_a_cue_switched_off_draws_it_as_zero(tmp_path: Path) -> None:
    """The README's ``cues:`` example switches tracking off: ``virtual`` ran, then its plot raised KeyError."""
    cfg = load().replace(cues={"tracking": {"enabled": False}})
    _, log = run_virtual(cfg, duration=0.05)
    assert "tracking" not in log.results[-1].wrenches
    out = tmp_path / "virtual.png"
    plot_virtual(log, cfg, out)
    assert out.stat().st_size > 0
