"""The compiled tick against the same Python functions run by the interpreter (NUMBA_DISABLE_JIT=1).

Both runs tick the controller on the same random states (every input present, pushes that reach
the limits); every output must agree to 1e-9 (relative to its scale).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from lapwrench.compiled_tick import CueError, ReadOnlyInputs
from lapwrench.config import Config
from lapwrench.controller import Controller, TickResult
from lapwrench.jit import jit_enabled
from lapwrench.sensors import (
    ForceTorqueReading,
    InputEvent,
    InstrumentObservation,
    RobotReading,
    SensorFrame,
    TactileReading,
    ValidInputs,
)
from lapwrench.spatial import Wrench
from lapwrench.virtual import home_pose
from lapwrench.wrenches.base import Cue, TickContext

SCRIPT = Path(__file__).with_name("compiled_ticks.py")


def _run(out: Path, disable_jit: bool, extra: bool) -> dict[str, np.ndarray]:
    env = dict(os.environ, NUMBA_DISABLE_JIT="1" if disable_jit else "0")
    cmd = [sys.executable, str(SCRIPT), str(out), *(["--extra"] if extra else [])]
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    with np.load(out) as z:
        return {k: z[k] for k in z.files}


@pytest.mark.slow  # compiled and uncompiled ticks in subprocesses
@pytest.mark.parametrize("extra", [False, True], ids=["one-call", "with-extra-source"])
def test_compiled_tick_equals_the_interpreted_one(tmp_path: Path, extra: bool) -> None:
    compiled = _run(tmp_path / "jit.npz", disable_jit=False, extra=extra)
    interpreted = _run(tmp_path / "py.npz", disable_jit=True, extra=extra)
    assert compiled.pop("jit")[0] and not interpreted.pop("jit")[0]  # really one of each
    assert compiled.keys() == interpreted.keys()
    assert compiled["q_ref"].shape[0] >= 900
    for key, a in compiled.items():
        b = interpreted[key]
        scale = max(1.0, float(np.abs(b).max()))
        np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-9 * scale, err_msg=key)
    if extra:
        assert np.abs(compiled["W_pull"]).max() > 1.0  # the extra source acted


def test_the_jit_is_on_in_the_test_process() -> None:
    assert jit_enabled()


# -- what a plugin cue returns is checked ----------------------------------------------------------
class Hostile(Cue):
    """A plugin cue returning ``self.value`` (or raising it), with ``self.damping`` as its damping matrix."""

    telemetry_fields = ("x",)

    def __init__(self, cfg: Config, value: object, damping: object = None, telemetry: object = (1.0,)) -> None:
        super().__init__("hostile", None, cfg)
        self.value, self.damping, self.values = value, damping, telemetry
        self.raise_after = 0.0  # s: an exception value is raised from this time on

    def compute(self, ctx: TickContext) -> Wrench:
        if isinstance(self.value, Exception):
            if ctx.time >= self.raise_after:
                raise self.value
            return Wrench.zero(ctx.geometry.p_G)
        return self.value  # type: ignore[return-value]

    def damping_matrix(self, ctx: TickContext) -> object:  # type: ignore[override]
        return self.damping

    def telemetry(self, ctx: TickContext, wrench: Wrench) -> object:  # type: ignore[override]
        return self.values


def _tick_with(cue: Hostile) -> tuple[TickResult, list[InputEvent]]:
    ctrl = Controller(cue.cfg, extra_cues=[cue])
    q0 = home_pose(cue.cfg.robot.kind)
    ctrl.reset(q0)
    assert ctrl.ref is not None
    r = ctrl.tick(SensorFrame(0.0, robot=RobotReading(q0, np.zeros(q0.shape[0]), None, 0.0)))
    return r, list(ctrl.events)


NAN3 = np.array([np.nan, 0.0, 0.0])


@pytest.mark.parametrize(
    ("value", "damping"),
    [
        (Wrench(NAN3, np.zeros(3), np.zeros(3)), None),
        (Wrench(np.zeros(3), np.full(3, np.inf), np.zeros(3)), None),
        (Wrench(np.zeros(3), np.ones(3), NAN3), None),
        (Wrench(np.zeros(3), np.zeros(3), np.zeros(3)), np.full((6, 6), np.nan)),
    ],
    ids=["nan-moment", "inf-force", "nan-point", "nan-damping"],
)
def test_a_non_finite_plugin_output_is_dropped_for_the_tick_and_reported(cfg: Config, value: Wrench,
                                                                         damping: object) -> None:
    r, events = _tick_with(Hostile(cfg, value, damping))
    assert np.all(np.isfinite(r.q_ref)) and np.all(np.isfinite(r.wrenches["hostile"]))
    assert any(e.source == "cues" and "hostile" in e.message for e in events)


@pytest.mark.parametrize(
    ("value", "damping", "telemetry", "words"),
    [(np.zeros(6), None, (1.0,), "not a Wrench"),
     (Wrench(np.zeros(2), np.zeros(3), np.zeros(3)), None, (1.0,), "3-vectors"),
     (Wrench(np.zeros(3), ["a", "b", "c"], np.zeros(3)), None, (1.0,), "3-vectors"),  # type: ignore[arg-type]
     (Wrench(np.zeros(3), ["1", "2", "3"], np.zeros(3)), None, (1.0,), "3-vectors"),  # type: ignore[arg-type]
     (Wrench(np.array([True, False, True]), np.zeros(3), np.zeros(3)), None, (1.0,), "3-vectors"),
     (Wrench(np.zeros(3), np.zeros(3), np.zeros(3)), np.eye(3), (1.0,), "6 x 6"),
     (Wrench(np.zeros(3), np.zeros(3), np.zeros(3)), np.full((6, 6), "1"), (1.0,), "6 x 6"),
     (Wrench(np.zeros(3), np.zeros(3), np.zeros(3)), None, (1.0, 2.0), "telemetry values"),
     (Wrench(np.zeros(3), np.zeros(3), np.zeros(3)), None, ("x",), "numbers"),
     (Wrench(np.zeros(3), np.zeros(3), np.zeros(3)), None, ("1.5",), "numbers"),
     (Wrench(np.zeros(3), np.zeros(3), np.zeros(3)), None, (10**400,), "numbers")],
    ids=["array", "short-moment", "text-force", "numeric-text-force", "bool-moment", "small-damping", "text-damping",
         "telemetry-count", "telemetry-text", "telemetry-numeric-text", "telemetry-huge-int"],
)
def test_a_malformed_plugin_output_is_a_cue_error(cfg: Config, value: object, damping: object, telemetry: object,
                                                  words: str) -> None:
    with pytest.raises(CueError, match=words):
        _tick_with(Hostile(cfg, value, damping, telemetry))


def test_a_plugin_that_fails_at_once_fails_the_build_before_anything_moves(cfg: Config) -> None:
    with pytest.raises(CueError, match="cue 'hostile' compute: ValueError: boom"):  # the plugin named
        Controller(cfg, extra_cues=[Hostile(cfg, ValueError("boom"))])  # the warm-up tick runs every cue


def test_an_exception_in_a_plugin_reaches_the_loop_which_stops_to_rest(cfg: Config) -> None:
    from lapwrench.virtual import run_virtual

    cue = Hostile(cfg, ValueError("boom"))
    cue.raise_after = 0.05
    ctrl = Controller(cfg, extra_cues=[cue])
    _, log = run_virtual(cfg, duration=0.2, controller=ctrl)
    assert log.alarm is not None and "cue 'hostile' compute: ValueError: boom" in log.alarm


class Recorder(Cue):
    """A plugin cue with a zero wrench that keeps copies of what it read each tick."""

    def __init__(self, cfg: Config) -> None:
        super().__init__("recorder", None, cfg)
        self.seen: list[tuple[np.ndarray, np.ndarray, float]] = []

    def compute(self, ctx: TickContext) -> Wrench:
        self.seen.append((ctx.kin.q.copy(), ctx.geometry.p_G.copy(), ctx.geometry.s_star))
        return Wrench.zero(ctx.geometry.p_G)


def test_python_cues_read_this_tick_and_what_the_tick_returns_outlives_the_next(cfg: Config) -> None:
    cue = Recorder(cfg)
    ctrl = Controller(cfg, extra_cues=[cue])
    q0 = home_pose(cfg.robot.kind)
    ctrl.reset(q0)
    results, kept, refs = [], [], []
    for k in range(3):
        assert ctrl.ref is not None
        refs.append(ctrl.ref.q.copy())
        q = q0 + 0.01 * k
        r = ctrl.tick(SensorFrame(0.001 * k, robot=RobotReading(q, np.zeros(q.shape[0]), np.ones(3), 0.001 * k)))
        results.append(r)
        kept.append((r.e_R.copy(), r.p_R.copy(), r.p_G.copy(), r.residual_lateral.copy()))
    for r, (e_R, p_R, p_G, F_lat) in zip(results, kept, strict=True):  # unchanged by the later ticks
        for a, b in ((r.e_R, e_R), (r.p_R, p_R), (r.p_G, p_G), (r.residual_lateral, F_lat)):
            np.testing.assert_array_equal(a, b)
    seen = cue.seen[-3:]  # the warm-up ran the cue too
    for (q_seen, p_G_seen, s_star), r, q_ref in zip(seen, results, refs, strict=True):
        np.testing.assert_array_equal(q_seen, q_ref)  # the kinematics at this tick's reference
        np.testing.assert_array_equal(p_G_seen, r.p_G)  # the geometry of this tick
        assert s_star > 0.0  # the closest point's parameter, not the placeholder
    assert not np.array_equal(seen[0][1], seen[2][1])  # the ticks differed


class Writer(Cue):
    """A plugin cue that writes into one array of what it reads (``target``: a path from ``ctx``) after t = 0."""

    def __init__(self, cfg: Config, target: str) -> None:
        super().__init__("writer", None, cfg)
        self.target = target

    def compute(self, ctx: TickContext) -> Wrench:
        if ctx.time > 0.0:
            obj: object = ctx
            for part in self.target.split("."):
                obj = getattr(obj, part)
            np.asarray(obj)[...] += 0.5  # type: ignore[index]
        return Wrench.zero(ctx.geometry.p_G)


def _full_frame(t: float, q: np.ndarray) -> SensorFrame:
    z = np.zeros(3)
    return SensorFrame(
        t, ForceTorqueReading(np.array([1.0, 0.0, 0.0]), z.copy(), t), TactileReading(np.full(64, 50.0), t),
        InstrumentObservation(np.array([[300.0, 200.0]]), t), RobotReading(q, np.zeros(q.shape[0]), z.copy(), t),
    )


@pytest.mark.parametrize("target", [
    "kin.q", "kin.dq", "kin.M", "kin.J_E", "kin.p_C", "geometry.p_R", "geometry.J_G", "geometry.p_G",
    "inputs.robot.q", "inputs.robot.external_force", "inputs.ft.force", "inputs.tactile.values",
    "inputs.instruments.points",
])
def test_a_plugin_cannot_write_into_the_arrays_it_reads(cfg: Config, target: str) -> None:
    """The tick's kinematics and geometry are what the motion stage reads after the cues, and the readings are
    the sources' own arrays (the measured q is the supervisor's): a write is an error (the loop's alarm and stop
    to rest), and changes none of them."""
    ctrl = Controller(cfg, extra_cues=[Writer(cfg, target)])
    q0 = home_pose(cfg.robot.kind)
    ctrl.reset(q0)
    assert ctrl.ref is not None
    frame = _full_frame(0.001, q0.copy())
    readings = [a.copy() for a in (frame.robot.q, frame.robot.external_force, frame.tactile.values,  # type: ignore[union-attr]
                                   frame.instruments.points)]  # type: ignore[union-attr]
    with pytest.raises(CueError, match="read-only"):
        ctrl.tick(frame)
    after = (frame.robot.q, frame.robot.external_force, frame.tactile.values, frame.instruments.points)  # type: ignore[union-attr]
    for before, now in zip(readings, after, strict=True):
        np.testing.assert_array_equal(now, before)


def test_a_plugin_writing_into_the_kinematics_stops_the_loop_without_a_jump(cfg: Config) -> None:
    from lapwrench.virtual import run_virtual

    ctrl = Controller(cfg, extra_cues=[Writer(cfg, "kin.q")])
    _, log = run_virtual(cfg, duration=0.05, controller=ctrl)
    assert log.alarm is not None and "read-only" in log.alarm
    q = np.array([home_pose(cfg.robot.kind)] + [r.q_ref for r in log.results])
    assert np.all(np.abs(np.diff(q, axis=0)) <= ctrl.model.limits.velocity * cfg.robot.dt)


def test_the_cues_inputs_are_read_only_and_a_reading_handed_on_again_is_viewed_once() -> None:
    view = ReadOnlyInputs()
    tactile, points = TactileReading(np.full(64, 50.0), 0.0), InstrumentObservation(np.array([[1.0, 2.0]]), 0.0)
    first = view(ValidInputs(tactile=tactile, instruments=points, events=[InputEvent(0.0, "ft", "stale")]))
    second = view(ValidInputs(tactile=tactile, instruments=InstrumentObservation(np.array([[3.0, 4.0]]), 0.0)))
    assert second.tactile is first.tactile and second.instruments is not first.instruments
    assert first.tactile is not None and second.instruments is not None
    assert not first.tactile.values.flags.writeable and not second.instruments.points.flags.writeable
    np.testing.assert_array_equal(second.instruments.points, [[3.0, 4.0]])
    assert tactile.values.flags.writeable  # the source's own array is left as it was
    first.events.clear()  # a cue's copy of the events
    assert view(ValidInputs(events=[InputEvent(0.0, "ft", "stale")])).events == [InputEvent(0.0, "ft", "stale")]


@pytest.mark.parametrize("damping", [-10.0 * np.eye(6), np.eye(6) + 5.0 * np.fliplr(np.eye(6))],
                         ids=["negative", "indefinite"])
def test_a_plugin_damping_matrix_that_feeds_energy_in_is_dropped_and_reported(cfg: Config,
                                                                               damping: np.ndarray) -> None:
    from lapwrench.virtual import run_virtual

    ctrl = Controller(cfg, extra_cues=[Hostile(cfg, Wrench(np.zeros(3), np.zeros(3), np.zeros(3)), damping)])
    _, log = run_virtual(cfg, duration=0.5, controller=ctrl)  # nobody touches the scope
    q = np.array([r.q_ref for r in log.results])
    assert log.alarm is None and np.abs(q - home_pose(cfg.robot.kind)).max() < 1e-6  # it stays where it is
    assert any(e.source == "cues" and "positive semi-definite" in e.message for e in ctrl.events)


def test_a_plugin_damping_matrix_that_is_semi_definite_is_used(cfg: Config) -> None:
    n = np.array([0.0, 0.0, 0.0, 1.0, 0.0, 0.0])
    _, events = _tick_with(Hostile(cfg, Wrench(np.zeros(3), np.zeros(3), np.zeros(3)), 50.0 * np.outer(n, n)))
    assert not [e for e in events if e.source == "cues"]
