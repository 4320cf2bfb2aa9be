"""The controller tick: bad input at its edge never reaches the command; results do not share memory."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from fake_plugins import Spring, install

from lapwrench.config import from_dict, load
from lapwrench.config_ranges import ConfigError
from lapwrench.controller import EXPLICIT_STEP_LIMIT, Controller, check_explicit_step, explicit_step_ratio
from lapwrench.inputs import Reading
from lapwrench.robot.limits import limit_usage
from lapwrench.sensors import (
    ForceTorqueReading,
    InstrumentObservation,
    RobotReading,
    SensorFrame,
    TactileReading,
)
from lapwrench.virtual import DEFAULT_Q0


def _frame_at(ctrl: Controller, k: int) -> SensorFrame:
    assert ctrl.ref is not None
    t = k * ctrl.dt
    return SensorFrame(
        t, ForceTorqueReading(np.array([3.0, 1.0, 0.0]), np.zeros(3), t), TactileReading(np.full(64, 80.0), t),
        InstrumentObservation(np.array([[400.0, 260.0]]), t), RobotReading(ctrl.ref.q, ctrl.ref.dq, None, t),
    )


def _result_arrays(r: object) -> list[np.ndarray]:
    fields = r._asdict()  # type: ignore[attr-defined]
    arrays = [v for v in fields.values() if isinstance(v, np.ndarray)]
    return arrays + list(fields["wrenches"].values())

NAN, INF = float("nan"), float("inf")
GRIP = TactileReading(np.full(64, 62.5))
FT = ForceTorqueReading(np.array([5.0, 0.0, 0.0]), np.zeros(3))
FAR = InstrumentObservation(np.array([[600.0, 400.0]]))


def _frame(t: float, **kw: Any) -> SensorFrame:
    base = {"ft": FT, "tactile": GRIP, "instruments": InstrumentObservation(FAR.points, t)}
    base.update(kw)
    return SensorFrame(t, **base)


BAD = {
    "ft": [
        ForceTorqueReading(np.array([NAN, 0, 0]), np.zeros(3)),
        ForceTorqueReading(np.array([0, INF, 0]), np.zeros(3)),
        ForceTorqueReading(np.array([500.0, 0, 0]), np.zeros(3)),
        ForceTorqueReading(np.zeros(3), np.array([0, 0, 50.0])),
        ForceTorqueReading(np.zeros(2), np.zeros(3)),
        ForceTorqueReading(np.array(["5", "0", "0"]), np.zeros(3)),  # numeric strings are not numbers
        ForceTorqueReading(np.array([5.0 + 1j, 0, 0]), np.zeros(3)),  # complex
        ForceTorqueReading(None, np.zeros(3)),  # type: ignore[arg-type]
        ForceTorqueReading([[5.0, 0.0], [0.0]], np.zeros(3)),  # type: ignore[arg-type]  # ragged
    ],
    "tactile": [
        TactileReading(np.full(64, NAN)),
        TactileReading(np.full(64, 300.0)),
        TactileReading(np.full(64, -1.0)),
        TactileReading(np.full(63, 100.0)),
        TactileReading(np.full(64, True)),  # booleans are not pressures
        TactileReading(["62.5"] * 64),  # type: ignore[arg-type]
    ],
    "instruments": [
        InstrumentObservation(np.array([[NAN, 100.0]])),
        InstrumentObservation(np.array([[INF, 100.0]])),
        InstrumentObservation(np.array([[700.0, 100.0]])),
        InstrumentObservation(np.array([[-5.0, 100.0]])),
        InstrumentObservation(np.array([1.0, 2.0, 3.0])),
        InstrumentObservation([[600.0, 400.0], [100.0]]),  # type: ignore[arg-type]  # ragged
        InstrumentObservation([["600", "400"]]),  # type: ignore[arg-type]
        InstrumentObservation(np.tile([[600.0, 400.0]], (100, 1))),  # 100 at one corner: 1000 N by eq 8
    ],
}
WRENCH_OF = {"ft": "interaction", "tactile": "interaction", "instruments": "tracking"}


@pytest.mark.parametrize(("source", "index"), [(s, i) for s, v in BAD.items() for i in range(len(v))])
def test_bad_reading_zeroes_its_wrench_and_is_reported(source: str, index: int) -> None:
    cfg = load()
    ctrl = Controller(cfg)
    ctrl.reset(DEFAULT_Q0)
    good = ctrl.tick(_frame(0.0))
    assert np.any(good.wrenches[WRENCH_OF[source]])
    refs = [good.q_ref]
    for k in range(1, 200):
        bad = BAD[source][index]
        if source == "instruments":
            bad = InstrumentObservation(bad.points, k * 1e-3)
        res = ctrl.tick(_frame(k * 1e-3, **{source: bad}))
        assert not np.any(res.wrenches[WRENCH_OF[source]])
        assert any(e.source == source for e in res.events)
        assert np.all(np.isfinite(res.q_ref)) and np.all(np.isfinite(res.tau))
        refs.append(res.q_ref)
    usage = limit_usage(np.array(refs), ctrl.dt, ctrl.model.limits, DEFAULT_Q0)
    assert max(usage["velocity"], usage["acceleration"], usage["jerk"]) <= 1.0


def test_stale_detection_counts_as_none() -> None:
    cfg = load()
    ctrl = Controller(cfg)
    ctrl.reset(DEFAULT_Q0)
    res = ctrl.tick(SensorFrame(1.0, instruments=InstrumentObservation(FAR.points, 0.5)))
    assert not np.any(res.wrenches["tracking"])
    assert any("older" in e.message for e in res.events)


@pytest.mark.parametrize(
    "robot",
    [
        RobotReading(np.full(7, NAN), np.zeros(7), np.zeros(3)),
        RobotReading(DEFAULT_Q0, np.full(7, INF), np.zeros(3)),
        RobotReading(DEFAULT_Q0 + 10.0, np.zeros(7), np.zeros(3)),
        RobotReading(DEFAULT_Q0, np.full(7, 50.0), np.zeros(3)),
        RobotReading(DEFAULT_Q0[:6], np.zeros(7), np.zeros(3)),
    ],
)
def test_bad_robot_state_pauses_adaptation_and_is_reported(robot: RobotReading) -> None:
    cfg = load()
    ctrl = Controller(cfg)
    ctrl.reset(DEFAULT_Q0)
    p0 = ctrl.rcm.p_R.copy()
    for k in range(100):
        res = ctrl.tick(SensorFrame(k * 1e-3, ft=FT, robot=robot))
        assert any(e.source == "robot" for e in res.events)
        assert np.all(np.isfinite(res.q_ref))
    np.testing.assert_allclose(ctrl.rcm.p_R, p0)


def test_bad_external_force_is_rejected_but_joint_state_kept() -> None:
    ctrl = Controller(load())
    ctrl.reset(DEFAULT_Q0)
    res = ctrl.tick(SensorFrame(0.0, ft=FT, robot=RobotReading(DEFAULT_Q0, np.zeros(7), np.array([NAN, 0, 0]))))
    assert any(e.source == "external_force" for e in res.events)


def test_valid_residual_moves_the_rcm_point() -> None:
    ctrl = Controller(load())
    ctrl.reset(DEFAULT_Q0)
    p0 = ctrl.rcm.p_R.copy()
    wall = np.array([12.0, 0.0, 0.0])
    for k in range(200):
        ctrl.tick(SensorFrame(k * 1e-3, ft=ForceTorqueReading(np.zeros(3), np.zeros(3)),
                              robot=RobotReading(DEFAULT_Q0, np.zeros(7), wall)))
    assert ctrl.rcm.p_R[0] - p0[0] > 1e-3


def test_tick_before_reset_is_an_error() -> None:
    with pytest.raises(RuntimeError, match="reset"):
        Controller(load()).tick(SensorFrame(0.0))


def test_reset_rejects_bad_configuration() -> None:
    ctrl = Controller(load())
    with pytest.raises(ValueError, match="finite"):
        ctrl.reset(np.full(7, NAN))
    with pytest.raises(ValueError, match="limits"):
        ctrl.reset(DEFAULT_Q0 + 5.0)


def test_event_memory_is_bounded_but_every_event_is_counted() -> None:
    from lapwrench.controller import MAX_KEPT_EVENTS

    ctrl = Controller(load())
    ctrl.reset(DEFAULT_Q0)
    bad = TactileReading(np.full(64, NAN))
    n = MAX_KEPT_EVENTS + 500
    for k in range(n):
        ctrl.tick(SensorFrame(k * 1e-3, tactile=bad))
    assert len(ctrl.events) == MAX_KEPT_EVENTS
    assert ctrl.event_counts["tactile"] == n


@pytest.mark.parametrize("stamp", [None, "0.1", float("nan"), 39.0, -39.0, pytest.param(10**400, id="10**400")])
def test_a_detection_with_a_bad_stamp_is_not_used(stamp: object) -> None:
    """No stamp, a string, NaN, 39 s in the future or in the past, an int beyond any float (raised
    OverflowError, found by the fuzz suite): the detection is dropped with an event."""
    ctrl = Controller(load())
    ctrl.reset(DEFAULT_Q0)
    res = ctrl.tick(_frame(0.0, instruments=InstrumentObservation(FAR.points, stamp)))  # type: ignore[arg-type]
    assert not np.any(res.wrenches["tracking"]) and any(e.source == "instruments" for e in res.events)


def test_a_nan_frame_time_uses_no_detection() -> None:
    ctrl = Controller(load())
    ctrl.reset(DEFAULT_Q0)
    res = ctrl.tick(SensorFrame(float("nan"), ft=FT, tactile=GRIP, instruments=InstrumentObservation(FAR.points, 0.0)))
    assert not np.any(res.wrenches["tracking"])


# -- the controller ------------------------------------------------------------------------------
def test_tick_results_do_not_share_memory_across_ticks() -> None:
    """Every tick's arrays are its own: a consumer may keep a TickResult while the controller runs on."""
    ctrl = Controller(load())
    ctrl.reset(DEFAULT_Q0)
    results = []
    for k in range(3):
        results.append(ctrl.tick(_frame_at(ctrl, k)))
    first = [np.array(a, copy=True) for a in _result_arrays(results[0])]
    for a, b in zip(_result_arrays(results[0]), first, strict=True):
        np.testing.assert_array_equal(a, b)
    for a in _result_arrays(results[0]):
        assert not any(np.shares_memory(a, b) for b in _result_arrays(results[1]))


# -- cues: plugin cues in the tick (the Controller builds them from the config's cues: section) ----
@pytest.fixture
def plugins(monkeypatch: pytest.MonkeyPatch) -> None:
    """The fake plugin cues and input of tests/fake_plugins.py, as if installed."""
    install(monkeypatch)


def _run(ctrl: Controller, ticks: int, extra: dict | None = None) -> list:  # type: ignore[type-arg]
    """Ticks of the controller on its own reference (the virtual model), with optional extra readings."""
    lim = ctrl.model.limits
    q0 = np.array([0.0, 0.2, 0.0, -2.0, 0.0, 2.2, 0.785])[: ctrl.model.nq]
    assert np.all(q0 > lim.position_lower) and np.all(q0 < lim.position_upper)
    ctrl.reset(q0)
    out = []
    for k in range(ticks):
        t = k * ctrl.dt
        assert ctrl.ref is not None
        robot = RobotReading(ctrl.ref.q, ctrl.ref.dq, None, t)
        extra_now = {name: Reading(np.asarray(v(t)), t) for name, v in (extra or {}).items()}
        out.append(ctrl.tick(SensorFrame(t, robot=robot, extra=extra_now)))
    return out


@pytest.mark.usefixtures("plugins")
def test_a_null_space_plugin_cue_moves_the_camera_toward_its_target_and_keeps_the_rcm() -> None:
    cfg = from_dict({"cues": {"spring": {"stiffness": 200.0, "target": [0.6, 0.2, 0.2]}}})
    ctrl = Controller(cfg)
    results = _run(ctrl, 1500)
    first, last = results[0].telemetry["spring"][0], results[-1].telemetry["spring"][0]  # type: ignore[index]
    assert last < first - 0.005
    assert max(r.rcm_error for r in results) < 1e-3
    assert set(results[-1].wrenches) == {"rcm", "interaction", "tracking", "viscous", "spring"}


@pytest.mark.usefixtures("plugins")
def test_without_the_plugin_the_camera_stays() -> None:
    ctrl = Controller(load())
    results = _run(ctrl, 300)
    assert np.allclose(results[-1].q_ref, results[0].q_ref, atol=1e-6)


@pytest.mark.usefixtures("plugins")
def test_extra_cues_built_in_code_join_the_configured_ones() -> None:
    cfg = load()
    ctrl = Controller(cfg, extra_cues=[Spring("pull", Spring.Params(), cfg)])
    assert [c.name for c in ctrl.cues][-1] == "pull" and "pull" in _run(ctrl, 2)[-1].wrenches


@pytest.mark.usefixtures("plugins")
def test_two_cues_with_one_name_are_refused() -> None:
    cfg = from_dict({"cues": {"spring": {}}})
    with pytest.raises(ValueError, match="unique"):
        Controller(cfg, extra_cues=[Spring("spring", Spring.Params(), cfg)])


@pytest.mark.usefixtures("plugins")
def test_a_task_space_cue_moves_the_pivot_only_sideways_and_keeps_the_null_space_free() -> None:
    cfg = from_dict({"cues": {"sideways": {}}})
    results = _run(Controller(cfg), 400)
    e = np.array([r.e_R for r in results])
    assert np.linalg.norm(e[-1]) > 1e-3  # the 3 N at p_R holds the shaft off the RCM point: it acts in the task
    assert abs(e[-1][0]) > 5 * abs(e[-1][1])  # along x, as pushed


@pytest.mark.usefixtures("plugins")
def test_a_switched_off_paper_cue_gives_no_wrench_and_no_mode() -> None:
    cfg = load().replace(cues={"tracking": {"enabled": False}})
    ctrl = Controller(cfg)
    ctrl.reset(np.array([0.0, 0.2, 0.0, -2.0, 0.0, 2.2, 0.785]))
    assert ctrl.ref is not None
    obs = InstrumentObservation(np.array([[600.0, 50.0]]), 0.0)
    r = ctrl.tick(SensorFrame(0.0, instruments=obs, robot=RobotReading(ctrl.ref.q, ctrl.ref.dq, None, 0.0)))
    assert "tracking" not in r.wrenches and r.mode == "idle"


@pytest.mark.usefixtures("plugins")
def test_a_registered_input_reaches_its_cue_only_while_valid() -> None:
    cfg = from_dict({"cues": {"pedal_hold": {}}})
    ctrl = Controller(cfg)
    pressed = _run(ctrl, 3, {"pedal": lambda t: [1.0]})[-1]
    assert pressed.wrenches["pedal_hold"][5] < 0.0
    for bad in ([float("nan")], [2.0], [1.0, 1.0]):
        r = _run(ctrl, 2, {"pedal": lambda t, b=bad: b})[-1]
        assert np.allclose(r.wrenches["pedal_hold"], 0.0)
        assert any(e.source == "pedal" for e in r.events)


@pytest.mark.usefixtures("plugins")
def test_a_reading_of_an_input_no_cue_asked_for_is_dropped_with_an_event() -> None:
    r = _run(Controller(load()), 1, {"sonar": lambda t: [1.0]})[-1]
    assert any(e.source == "inputs" and "sonar" in e.message for e in r.events)


@pytest.mark.slow
@pytest.mark.usefixtures("plugins")
def test_the_simulated_loop_feeds_a_registered_input_from_its_spec_and_traces_every_cue() -> None:
    from lapwrench.sim.loop import ClosedLoop, Trace

    loop = ClosedLoop(from_dict({"cues": {"pedal_hold": {}, "spring": {}}}))
    trace = Trace()
    for _ in range(150):  # the fake pedal goes down at 0.05 s
        loop.record(trace, loop.step(0.0))
    pedal = trace["cue:pedal_hold"][:, 5]
    assert pedal[0] == 0.0 and pedal[-1] < 0.0
    assert trace["cue:spring.distance"].shape == (150,) and "cue:tracking" in trace


def test_the_explicit_step_is_refused_where_it_cannot_integrate_the_viscous_damping() -> None:
    """The printed Euler step with the printed k_t = 150 N m s: dt M^-1 J^T D J reaches about 30 on the Panda,
    the joint accelerations flip sign every other tick. Refused before the controller exists (its construction
    warms the tick up at a reset), naming the key and a k_t that fits."""

    with pytest.raises(ConfigError, match=r"motion.integrator: explicit.*viscous.k_t.*semi_implicit") as err:
        Controller(load().replace(motion={"integrator": "explicit"}))
    assert err.value.key == "motion.integrator"
    with pytest.raises(ConfigError, match=r"viscous\.k_t_unguided"):  # the damping without the hand, too
        Controller(load().replace(motion={"integrator": "explicit"}, viscous={"k_t": 2.0, "k_t_unguided": 150.0}))
    Controller(load()).reset(DEFAULT_Q0)  # semi_implicit, the default: any damping


def test_the_explicit_step_within_its_bound_decays_the_velocity_and_is_accepted() -> None:
    """Below the bound the printed step's damping part I - dt M^-1 J^T D J has every eigenvalue inside the unit
    circle (the velocity decays, no sign flip each tick); past 2 one leaves it. (Measured on virtual runs: at
    ratio 1.3-1.7 no joint's acceleration flipped sign on more than 0.3 % of the ticks, at 2.3-4 on 43-99 %.)"""

    cfg = load().replace(motion={"integrator": "explicit"}, viscous={"k_t": 2.0, "k_t_unguided": 2.0})
    model = Controller(load()).model
    kin = model.kinematics(DEFAULT_Q0, np.zeros(7))
    for k_t, stable in ((2.0, True), (4.0, True), (20.0, False)):
        D = np.diag([k_t] * 3 + [cfg.viscous.k_f] * 3)
        ratio = explicit_step_ratio(kin.M, kin.J_E, D, cfg.robot.dt)
        step = np.eye(7) - cfg.robot.dt * np.linalg.solve(kin.M, kin.J_E.T @ D @ kin.J_E)
        assert (np.max(np.abs(np.linalg.eigvals(step))) <= 1.0) == stable == (ratio < 2.0)
    assert explicit_step_ratio(kin.M, kin.J_E, np.diag([2.0] * 3 + [cfg.viscous.k_f] * 3), cfg.robot.dt) <= (
        EXPLICIT_STEP_LIMIT
    )
    check_explicit_step(cfg, model, DEFAULT_Q0)  # accepted
    with pytest.raises(ConfigError):
        check_explicit_step(cfg.replace(viscous={"k_t": 20.0}), model, DEFAULT_Q0)
