"""The simulated session behind the page, stepped directly (no browser, no threads)."""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from lapwrench.config import Config
from lapwrench.controller import TickResult
from lapwrench.ui.inputs import UiInputError
from lapwrench.ui.session import Session


def run(session: Session, seconds: float) -> list[TickResult | None]:
    return [session.step() for _ in range(round(seconds * 1000))]


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(float(np.clip(a @ b, -1.0, 1.0))))


@pytest.fixture
def session(cfg: Config) -> Iterator[Session]:
    s = Session(cfg, seed=1)
    yield s
    s.closed.world.close()


def test_a_gripped_push_turns_the_scope_about_the_incision(session: Session) -> None:
    _, d0 = session.closed.world.shaft_axis()
    session.hand.set_grip_level("high")
    session.hand.set_push(0.0, 15.0)
    results = run(session, 1.5)
    _, d1 = session.closed.world.shaft_axis()
    assert angle_deg(d0, d1) > 1.0
    assert session.max_rcm_error < 0.002
    assert session.held is None
    assert results[-1] is not None and results[-1].mode == "handle"
    snap = session.snapshot
    assert snap is not None and snap.mode == "handle" and snap.delta > 1.5
    assert np.linalg.norm(snap.hand_force) == pytest.approx(15.0, rel=1e-6)
    names = [c.name for c in session.closed.controller.cues]
    assert set(snap.cue_forces) == set(names)
    assert {f"|F| {n}" for n in names} <= set(session.history.names())


def test_the_gizmo_turns_the_scope_without_pushing_along_the_shaft(session: Session) -> None:
    _, d0 = session.closed.world.shaft_axis()
    session.hand.set_grip_level("high")
    e1 = np.cross(d0, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    session.hand.set_gizmo(0.04 * e1 + 0.04 * d0)  # 12 N across the shaft and 12 N along it, as dragged
    for _ in range(15):
        run(session, 0.1)
        _, d = session.closed.world.shaft_axis()
        force = session.closed.world.hand_force()
        assert abs(force @ d) < 0.05, "the pull does not push the scope in or out"
        pull = session.hand.gizmo
        assert np.linalg.norm(force) == pytest.approx(np.linalg.norm(pull - (pull @ d) * d), rel=0.01)
    assert angle_deg(d0, d) > 1.0
    assert session.max_rcm_error < 0.0005
    assert session.held is None


def test_the_page_hand_is_set_again_after_a_scenario_and_follows_a_change(session: Session) -> None:
    session.hand.set_push(0.0, 10.0)
    session.play("view-adjustment")
    run(session, 0.2)
    session.stop_script()
    run(session, 0.01)
    _, d = session.closed.world.shaft_axis()
    np.testing.assert_allclose(session.closed.world.hand_force(), session.hand.wrench(d)[0], atol=0.05)
    session.hand.set_push(90.0, 4.0)
    run(session, 0.001)
    assert np.linalg.norm(session.closed.world.hand_force()) == pytest.approx(4.0)


def test_an_ungripped_push_barely_moves_the_scope(session: Session) -> None:
    _, d0 = session.closed.world.shaft_axis()
    session.hand.set_push(0.0, 15.0)
    run(session, 1.0)
    _, d1 = session.closed.world.shaft_axis()
    assert angle_deg(d0, d1) < 0.5
    assert session.snapshot is not None and session.snapshot.mode == "idle"


def test_every_tick_calls_the_per_cycle_callbacks(session: Session) -> None:
    seen: list[float] = []
    session.on_tick.append(lambda s, res: seen.append(s.time))
    run(session, 0.05)
    assert len(seen) == 50 and seen == sorted(seen)


def test_a_changed_hand_is_in_the_next_ticks_snapshot_and_announced_once(session: Session) -> None:
    """The page draws a push as soon as a snapshot shows it (ui/app.py), not at its next period."""
    calls: list[float] = []
    session.on_hand_snapshot.append(lambda: calls.append(session.time))
    run(session, 0.1)
    calls.clear()  # the first tick's hand counts as changed
    session.hand.set_grip_level("high")
    session.hand.set_push(0.0, 9.0)
    session.step()
    snap = session.snapshot
    assert snap is not None and snap.t == pytest.approx(session.time)
    assert np.linalg.norm(snap.hand_force) == pytest.approx(9.0)
    assert calls == [session.time]
    run(session, 0.05)  # the same hand: snapshots at their own rate, no more announcements
    assert len(calls) == 1
    session.hand.set_push(0.0, 9.0)  # set again to the same values: not a change
    run(session, 0.01)
    assert len(calls) == 1


def test_bad_instrument_values_are_refused_and_a_shown_instrument_is_tracked(session: Session) -> None:
    with pytest.raises(UiInputError):
        session.set_instrument(0, True, float("nan"), 0.0)
    with pytest.raises(UiInputError):
        session.set_instrument(5, True, 0.0, 0.0)
    assert not session.instruments[0].visible
    session.set_instrument(0, True, 0.04, 0.0)
    run(session, 0.5)
    snap = session.snapshot
    assert snap is not None and len(snap.detections) == 1
    assert snap.mode == "tracking"


def test_a_parameter_change_is_applied_at_rest(session: Session, cfg: Config) -> None:
    run(session, 0.1)
    session.request_config(cfg.replace(viscous={"k_t": 60.0}))
    assert session.config_pending
    run(session, 0.05)
    assert not session.config_pending
    assert session.cfg.viscous.k_t == 60.0
    assert session.closed.controller.cfg.viscous.k_t == 60.0
    run(session, 0.2)
    assert session.held is None


def test_a_parameter_change_sends_no_step_to_the_robot(session: Session, cfg: Config) -> None:
    """The change built a fresh supervisor started at the measured pose while the robot held the old
    reference, a tracking error away: 2.4x the acceleration and 9x the jerk limit in one cycle. Now the
    arm is stopped to rest and the new supervisor resumes from the held reference."""
    robot = session.closed.loop.robot
    sent: list[np.ndarray] = []
    command = robot.command

    def record(q: np.ndarray) -> None:
        sent.append(np.array(q, dtype=float))
        command(q)

    robot.command = record  # type: ignore[method-assign]
    session.hand.set_grip_level("high")
    session.hand.set_push(90.0, 10.0)
    run(session, 0.3)
    session.hand.release()
    run(session, 0.2)
    session.request_config(cfg.replace(viscous={"k_t": 60.0}))
    run(session, 0.3)
    assert not session.config_pending and session.held is None
    assert session.closed.controller.cfg.viscous.k_t == 60.0
    q = np.array(sent)
    v = np.diff(q, axis=0) / 1e-3
    a = np.diff(v, axis=0) / 1e-3
    j = np.diff(a, axis=0) / 1e-3
    lim = session.closed.controller.model.limits
    assert np.max(np.abs(v) / lim.velocity) < 1.0
    assert np.max(np.abs(a) / lim.acceleration) < 1.0
    assert np.max(np.abs(j) / lim.jerk) < 1.0 + 1e-6
    assert any(e.kind == "start" and "resumed" in e.message for e in session.closed.supervisor.events)


def test_a_reset_applies_accepted_parameters_not_yet_applied(session: Session, cfg: Config) -> None:
    """Parameters accepted while the arm moved, then Reset: the reset dropped them silently, while the
    page's parameter line turned to 'Parameters applied.' (it watches ``config_pending``)."""
    session.request_config(cfg.replace(viscous={"k_t": 60.0}))
    assert session.config_pending  # no tick yet: not applied
    session.reset()
    assert session.cfg.viscous.k_t == 60.0
    assert session.closed.controller.cfg.viscous.k_t == 60.0
    assert not session.config_pending
    session.request_config(cfg.replace(viscous={"k_t": 70.0}))
    session.reset(cfg.replace(viscous={"k_t": 80.0}))  # a configuration given to the reset wins
    assert session.cfg.viscous.k_t == 80.0


def test_a_hold_keeps_the_world_running_and_resume_restarts_the_loop(cfg: Config) -> None:
    session = Session(cfg.replace(safety={"max_rcm_error": 0.0001}), seed=2)
    session.hand.set_grip_level("high")
    session.hand.set_push(90.0, 25.0)
    run(session, 2.0)
    assert session.held is not None and session.alarms
    t = session.time
    assert run(session, 0.1)[-1] is None  # held cycles
    assert session.time > t
    session.hand.release()
    run(session, 0.3)
    session.resume()
    res = run(session, 0.1)
    assert session.held is None
    assert res[-1] is not None
    session.closed.world.close()


def test_the_incision_shift_moves_the_housing_and_reset_starts_over(session: Session) -> None:
    session.set_disturbance(True)
    run(session, 1.5)
    assert session.closed.world.housing_displacement()[1] > 0.003
    assert session.snapshot is not None and session.snapshot.disturbance
    session.reset()
    assert session.time == 0.0 and session.held is None and len(session.history) == 0
    run(session, 0.2)
    assert abs(session.closed.world.housing_displacement()[1]) < 1e-3


def test_the_scripted_view_adjustment_grips_and_turns(session: Session) -> None:
    _, d0 = session.closed.world.shaft_axis()
    session.play("view-adjustment")
    run(session, 1.0)
    snap = session.snapshot
    assert snap is not None and snap.script and snap.delta > 0.5
    assert angle_deg(d0, session.closed.world.shaft_axis()[1]) > 0.5


def test_with_the_projected_detector_the_loop_draws_no_frames(session: Session) -> None:
    cam = session.closed.camera
    assert cam is not None and not cam.draws  # the page's view renders on its own thread
    run(session, 0.1)
    assert session.closed.detection is not None and session.closed.detection.frames_captured == 3


def test_a_restart_takes_the_grips_weight_off_from_where_the_sensor_was_tared(session: Session, cfg: Config) -> None:
    """The F/T is tared once, at the loop's first start; a restart (here for a parameter change) at a pose
    the scope has since turned to must keep taking the grip's weight off relative to that first pose:
    gripped and untouched after the restart, the interaction force stays at the sensor's noise."""
    assert cfg.scope.grip_mass > 0.0
    ctrl = session.closed.controller
    tared = ctrl.model.kinematics(session.closed.q0, np.zeros(ctrl.model.nv)).R_H
    _, d0 = session.closed.world.shaft_axis()
    session.hand.set_grip_level("high")
    session.hand.set_push(0.0, 15.0)
    run(session, 6.0)
    session.hand.set_push(0.0, 0.0)
    run(session, 0.5)
    _, d1 = session.closed.world.shaft_axis()
    assert angle_deg(d0, d1) > 10.0
    session.request_config(cfg.replace(viscous={"k_t": 151.0}))
    run(session, 1.0)
    assert not session.config_pending and session.closed.controller.cfg.viscous.k_t == 151.0
    tare = session.closed.controller.compiled.tare  # type: ignore[union-attr]
    np.testing.assert_allclose(tare.R_H0, tared, atol=1e-12)
    F_h = [r.wrenches["interaction"][3:] for r in run(session, 1.0) if r is not None]
    assert len(F_h) == 1000 and np.linalg.norm(np.mean(F_h, axis=0)) < 0.1
