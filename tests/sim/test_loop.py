"""ClosedLoop's supervisor: it watches measured state, and a failing controller tick becomes a hold;
its records of a run."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.motion.reference_shaper import ReferenceState
from lapwrench.rcm.geometry import rcm_error
from lapwrench.robot.limits import limit_usage
from lapwrench.sim.loop import ClosedLoop, SafetyStopError, Trace
from lapwrench.sim.world import CONTROL_DT


def recording(loop: ClosedLoop) -> list[np.ndarray]:
    """Every command the robot receives, in order."""
    sent: list[np.ndarray] = []
    command = loop.robot.command

    def record(q: np.ndarray) -> None:
        sent.append(np.array(q, dtype=float))
        command(q)

    loop.robot.command = record  # type: ignore[method-assign]
    return sent


def assert_at_rest_inside_limits(loop: ClosedLoop, sent: list[np.ndarray]) -> None:
    assert loop.supervisor.at_rest
    cmds = np.array(sent)
    assert np.all(np.isfinite(cmds))
    assert np.allclose(cmds[-1], cmds[-2])  # the stop ended at rest
    usage = limit_usage(cmds, CONTROL_DT, loop.model.limits, loop.q0)
    assert usage["position_excess"] == 0 and max(usage["velocity"], usage["acceleration"], usage["jerk"]) <= 1, usage


def test_supervisor_holds_on_measured_rcm_error_while_the_reference_error_is_small() -> None:
    """The robot is displaced in the world (it no longer sits where the controller's reference
    is): the measured RCM error trips the 5 mm hold although the reference error stays ~0."""
    loop = ClosedLoop(load())
    sent = recording(loop)
    for _ in range(50):
        loop.step(0.0)
    q_shift = loop.world.q + np.r_[0.012, 0, 0, 0, 0, 0, 0]  # about 7 mm at the RCM point
    loop.world.reset(q_shift)
    with pytest.raises(SafetyStopError) as err:
        loop.step(0.0)
    assert str(err.value.reason).startswith("rcm_error: measured RCM error"), err.value.reason
    ctrl = loop.controller
    kin = ctrl.model.kinematics(ctrl.ref.q, ctrl.ref.dq)
    assert np.linalg.norm(rcm_error(kin, ctrl.rcm.p_R)) < 1e-3  # the controller's own error is small
    assert any(getattr(e, "kind", None) == "rcm_error" for e in loop.events)
    assert_at_rest_inside_limits(loop, sent)


def test_supervisor_holds_on_measured_insertion_depth() -> None:
    """p_R moved along the shaft (the reference RCM error stays 0): the measured depth is out of range."""
    loop = ClosedLoop(load())
    loop.step(0.0)
    _p, d_z = loop.world.shaft_axis()
    loop.controller.rcm.p_R = loop.controller.rcm.p_R + 0.05 * d_z  # depth 58 mm -> 8 mm
    with pytest.raises(SafetyStopError) as err:
        loop.step(0.0)
    assert str(err.value.reason).startswith("insertion_depth: measured insertion depth 8."), err.value.reason


def test_exception_in_the_controller_tick_stops_at_rest_with_an_alarm(monkeypatch: pytest.MonkeyPatch) -> None:
    loop = ClosedLoop(load())
    sent = recording(loop)
    loop.world.set_hand_wrench(force=[0.0, 8.0, 0.0])  # hand-guided: the arm moves
    for _ in range(400):
        loop.step(30.0)
    assert np.max(np.abs(loop.supervisor.command_state[1])) > 1e-3

    def broken(frame: object) -> None:
        raise np.linalg.LinAlgError("Singular matrix")

    monkeypatch.setattr(loop.controller, "tick", broken)
    with pytest.raises(SafetyStopError) as err:
        loop.step(30.0)
    assert err.value.reason == "controller_error: LinAlgError: Singular matrix"
    assert_at_rest_inside_limits(loop, sent)


def test_a_controller_that_cannot_keep_the_rcm_brakes_to_rest_then_the_supervisor_holds() -> None:
    """Joint boxes narrowed to nothing on six joints: the 2-row RCM task has no room, the controller
    latches its stop (cues off, null-space brake) and the supervisor holds once it is at rest."""
    loop = ClosedLoop(load())
    sent = recording(loop)
    ctrl = loop.controller
    _, d = loop.world.shaft_axis()
    push = np.cross(d, [0.0, 0.0, 1.0])
    push = 20.0 * push / np.linalg.norm(push)

    def frozen(state: ReferenceState, lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        lo, hi = lo.copy(), hi.copy()
        if loop.t > 0.2:  # from 0.2 s on, only joint 1 may change its acceleration toward zero
            lo[1:] = hi[1:] = np.clip(0.0, lo[1:], hi[1:])
        return lo, hi

    ctrl.bounds_hook = frozen
    with pytest.raises(SafetyStopError) as stop:
        for _ in range(3000):
            loop.world.set_hand_wrench(force=push)
            loop.step(grip_force=30.0)
    assert str(stop.value.reason).startswith("rcm_infeasible"), stop.value.reason
    assert ctrl.stopping
    assert_at_rest_inside_limits(loop, sent)
    assert loop.physical_rcm_error() < 2e-3


def test_a_record_holds_the_worlds_readings_of_that_tick() -> None:
    """Each row of the trace is the world as it read after that tick (the depth from the same poses
    as p_E, d_z and the incision), and every running cue's wrench."""
    loop = ClosedLoop(load(), seed=0)
    trace = Trace()
    w = loop.world
    for k in range(20):
        w.set_hand_wrench(force=[0.0, 2.0 * k, 0.0])
        res = loop.step(30.0)
        loop.record(trace, res, tick=k)
        assert trace["insertion_depth"][-1] == w.insertion_depth()
        assert trace["rcm_error_phys"][-1] == loop.physical_rcm_error()
        assert np.array_equal(trace["contact_force"][-1], w.contact_force())
        assert np.array_equal(trace["hand_force"][-1], [0.0, 2.0 * k, 0.0])
    assert list(trace["tick"]) == list(range(20)) and len(trace["t"]) == 20
    assert "cue:interaction" in trace and trace["cue:interaction"].shape == (20, 6)


def test_a_pickled_trace_holds_an_array_per_column_and_reads_the_same() -> None:
    """A trace crosses a process boundary (a demo worker's result) as one array per column, not as its
    rows' many small objects; unpickled it reads the same columns, each read a fresh array, and a
    column whose rows do not stack stays a list. Rows added afterwards extend it."""
    trace = Trace()
    for k in range(5):
        trace.add(t=k * 1e-3, mode="handle" if k % 2 else "idle", p=np.full(3, float(k)), ok=k > 2,
                  ragged=np.zeros(k + 1))
    copy = pickle.loads(pickle.dumps(trace))
    for key in ("t", "mode", "p", "ok"):
        assert isinstance(copy.columns[key], np.ndarray), key
        assert copy[key].dtype == trace[key].dtype and np.array_equal(copy[key], trace[key]), key
    assert isinstance(copy.columns["ragged"], list)
    assert [r.size for r in copy.columns["ragged"]] == [1, 2, 3, 4, 5]
    copy["p"][0] = -1.0  # a read is the caller's own array
    assert copy["p"][0, 0] == 0.0
    copy.add(t=5e-3, mode="idle", p=np.ones(3), ok=True, ragged=np.zeros(6))
    assert np.array_equal(copy["t"], np.arange(6) * 1e-3) and copy["p"].shape == (6, 3)
    assert list(copy["mode"]) == ["idle", "handle", "idle", "handle", "idle", "idle"]


def test_loops_of_one_configuration_run_alike_and_apart() -> None:
    """Loops of one configuration share its compiled scene, never their state: a loop stepped after
    another ran repeats its run exactly, and stepping it leaves the first one's world as it was."""
    cfg = load()
    runs = []
    for _ in range(2):
        loop = ClosedLoop(cfg, seed=1)
        loop.world.set_hand_wrench(force=[0.0, 6.0, 0.0])
        runs.append((loop, [loop.step(30.0).q_ref for _ in range(50)]))
    (first, a), (second, b) = runs
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    q = first.world.q
    second.step(30.0)
    assert np.array_equal(first.world.q, q) and first.world is not second.world


def _gripped_after_a_tilt(ctrl_grip_mass: float) -> tuple[float, float]:
    """A world whose grip weighs 0.1 kg beyond the handle sensor; a controller told ``ctrl_grip_mass``. The
    hand grips, tilts the scope with a 15 N push across the shaft, lets the push go and keeps gripping.
    Returns (tilt in degrees, |mean F_h| over the last second), F_h the interaction force (eq 6) in {B}: the
    mean, so that the sensor's zero-mean noise averages out and what pushes steadily is left."""
    from lapwrench.config import Config
    from lapwrench.sim.scene.config import SceneConfig

    world_cfg = Config()
    assert world_cfg.scope.grip_mass == pytest.approx(0.1)
    ctrl_cfg = world_cfg.replace(scope={"grip_mass": ctrl_grip_mass})
    c = ClosedLoop(ctrl_cfg, scene_config=SceneConfig.from_config(world_cfg))
    d0 = c.world.shaft_axis()[1].copy()
    across = np.cross(d0, [1.0, 0.0, 0.0])
    c.world.set_hand_wrench(force=15.0 * across / np.linalg.norm(across))
    for _ in range(8000):
        c.step(30.0)
    c.world.set_hand_wrench()
    for _ in range(1000):
        c.step(30.0)
    F_h = [c.step(30.0).wrenches["interaction"][3:] for _ in range(1000)]
    tilt = float(np.degrees(np.arccos(np.clip(c.world.shaft_axis()[1] @ d0, -1.0, 1.0))))
    c.world.close()
    return tilt, float(np.linalg.norm(np.mean(F_h, axis=0)))


def test_a_gripped_tilted_scope_feels_no_push_from_the_grips_weight() -> None:
    """Untouched but gripped, a scope tilted ~20° from where the F/T was tared: without the grip's weight
    taken off, eq (6) reads δ m g sin(tilt) (about 0.7 N here, the scope creeps); with it, only the
    tare's residual is left (0.1 N of bias averaged over 200 samples of 0.1 N noise, times δ)."""
    tilt, compensated = _gripped_after_a_tilt(0.1)
    _, raw = _gripped_after_a_tilt(0.0)
    assert tilt > 15.0
    assert raw > 0.5
    assert compensated < 0.1


def _gripped_after_a_drift(auto_zero_time: float) -> float:
    """After the tare the simulated F/T's bias drifts by 0.5 N (a strain-gauge sensor warming up); the
    handle stays untouched 10 s (5 of the zero's time constants), then is gripped without a push.
    Returns |mean F_h| over 1 s gripped."""
    from dataclasses import replace

    from lapwrench.config import Config

    c = ClosedLoop(Config().replace(interaction={"auto_zero_time": auto_zero_time}))
    n = c.ft.noise
    c.ft.noise = replace(n, force_bias=(n.force_bias[0] + 0.5, n.force_bias[1], n.force_bias[2]))
    for _ in range(10_000):
        c.step(0.0)
    for _ in range(300):
        c.step(30.0)
    F_h = [c.step(30.0).wrenches["interaction"][3:] for _ in range(1000)]
    c.world.close()
    return float(np.linalg.norm(np.mean(F_h, axis=0)))


def test_the_zero_kept_while_untouched_takes_out_a_drift_of_the_sensor() -> None:
    """Gripped without pushing after the F/T drifted 0.5 N: with the zero kept while nobody touched the
    grip the scope feels nothing steady; without it, δ times the drift (about 1 N) pushes it."""
    assert _gripped_after_a_drift(2.0) < 0.05
    assert _gripped_after_a_drift(0.0) > 0.8
