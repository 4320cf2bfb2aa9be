"""The cycle-record codec and log sink of the real-time process, through the shared-memory rings."""

from __future__ import annotations

import numpy as np

from lapwrench.hardware.log import CycleRecord
from lapwrench.hardware.rt import CycleCodec, ShmLogSink
from lapwrench.hardware.shm import Bus, unpack_event
from lapwrench.robot.description import MAX_JOINTS


def record(**over) -> CycleRecord:
    base = dict(
        t=1.0, robot_time=0.9, k=7, q=np.arange(7.0), dq=np.ones(7), tau_J=None, external_force=np.array([1.0, 2, 3]),
        ft_force=np.array([np.nan, 1.0, 2.0]), ft_torque=np.zeros(3), tactile=np.full(64, 40.0),
        instruments=np.array([[10.0, 20.0], [30.0, 40.0]]), wrenches={"rcm": np.arange(6.0), "interaction": np.ones(6)},
        mode="handle", delta=1.2, contacts=64, p_R=np.zeros(3), e_R=np.array([1e-3, 0, 0]), rcm_error=1e-3,
        rcm_error_measured=None, q_ref=np.zeros(7), q_cmd=np.full(7, 0.5), supervisor="running", alarm=False,
        compute_us=150.0, cycle_us=1000.0,
    )
    base.update(over)
    return CycleRecord(**base)


def test_cycle_records_survive_the_ring(bus: Bus) -> None:
    sink = ShmLogSink(bus.ring("log"), bus.ring("events"))
    sink.cycle(record())
    sink.cycle(record(k=8, mode="idle", instruments=None, ft_force=None, rcm_error_measured=2e-3))
    sink.cycle(record(k=9, q=np.zeros(3)))  # a malformed record: dropped and counted, never raised
    assert sink.encode_errors == 1
    decoder = CycleCodec()
    for row in bus.ring("events").take():
        _t, kind, message = unpack_event(row)
        assert kind == "__intern__"
        decoder.learn(message)
    a, b = (decoder.decode(r) for r in bus.ring("log").take())
    assert a.k == 7 and a.mode == "handle" and a.tau_J is None and a.rcm_error_measured is None
    assert np.isnan(a.ft_force[0]) and a.ft_force[1:].tolist() == [1.0, 2.0]  # NaN stays NaN, None stays None
    assert a.instruments.tolist() == [[10.0, 20.0], [30.0, 40.0]]
    assert set(a.wrenches) == {"rcm", "interaction"} and a.wrenches["rcm"].tolist() == list(range(6))
    assert b.mode == "idle" and b.instruments is None and b.ft_force is None and b.rcm_error_measured == 2e-3


def test_cycle_rows_record_the_joint_count(bus: Bus) -> None:
    """Rows have MAX_JOINTS places per joint vector and carry the arm's own count: a 6-joint arm's record
    comes back with 6 joints, one with more joints than a row holds is dropped and counted."""
    sink = ShmLogSink(bus.ring("log"), bus.ring("events"))
    six = {name: np.arange(6.0) + i for i, name in enumerate(("q", "dq", "tau_J", "q_ref", "q_cmd"))}
    sink.cycle(record(**six))
    too_many = np.zeros(MAX_JOINTS + 1)
    sink.cycle(record(q=too_many, dq=too_many, q_ref=too_many, q_cmd=too_many))
    assert sink.encode_errors == 1
    decoder = CycleCodec()
    for row in bus.ring("events").take():
        decoder.learn(unpack_event(row)[2])
    (got,) = (decoder.decode(r) for r in bus.ring("log").take())
    for name, value in six.items():
        assert getattr(got, name).tolist() == value.tolist(), name


def test_a_name_that_cannot_be_announced_is_retried(bus: Bus) -> None:
    events = bus.ring("events")
    sink = ShmLogSink(bus.ring("log"), events)
    filler = np.zeros(events.rows.shape[1], np.uint8)
    while events.push(filler):  # the event ring is full: no announcement gets through
        pass
    sink.cycle(record(mode="tracking"))
    events.take()  # the parent drains (the filler rows)
    sink.cycle(record(mode="tracking"))
    decoder = CycleCodec()
    for row in events.take():
        decoder.learn(unpack_event(row)[2])
    first, second = (decoder.decode(r) for r in bus.ring("log").take())
    assert first.mode == "?" and second.mode == "tracking"  # one row unnamed, never a wrong name


def test_the_bus_carries_every_cue_the_configuration_may_run() -> None:
    """A cycle row holds N_WRENCH wrenches; the cues: section allows at most that many cues."""
    from lapwrench.config_cues import MAX_CUES
    from lapwrench.hardware.rt.codec import CycleCodec

    assert MAX_CUES <= CycleCodec.N_WRENCH


def _decoded(bus: Bus) -> list[CycleRecord]:
    decoder = CycleCodec()
    for row in bus.ring("events").take():
        decoder.learn(unpack_event(row)[2])
    return [decoder.decode(r) for r in bus.ring("log").take()]


def test_the_cues_telemetry_crosses_the_bus_by_cue_name(bus: Bus) -> None:
    """What the 1 kHz child logs reaches the parent's log writer: every cue's values, in order, under
    its name (NaN stays NaN); a record without telemetry comes back with none."""
    sink = ShmLogSink(bus.ring("log"), bus.ring("events"))
    sink.cycle(record(telemetry={"zoom": (0.25, 1.0, np.nan), "keep_out": (0.3, 0.0)}))
    sink.cycle(record(k=8))
    a, b = _decoded(bus)
    assert list(a.telemetry) == ["zoom", "keep_out"] and a.telemetry["keep_out"] == (0.3, 0.0)
    assert a.telemetry["zoom"][:2] == (0.25, 1.0) and np.isnan(a.telemetry["zoom"][2])
    assert b.telemetry == {}


def test_a_row_holds_all_the_telemetry_a_configuration_may_log_and_cuts_the_rest(bus: Bus) -> None:
    from lapwrench.config_cues import MAX_CUE_TELEMETRY, MAX_TELEMETRY

    per_cue = [tuple(float(10 * c + i) for i in range(MAX_CUE_TELEMETRY)) for c in range(CycleCodec.N_WRENCH)]
    most = {f"cue{c}": per_cue[c] for c in range(MAX_TELEMETRY // MAX_CUE_TELEMETRY)}
    sink = ShmLogSink(bus.ring("log"), bus.ring("events"))
    sink.cycle(record(telemetry=most))
    sink.cycle(record(telemetry={f"cue{c}": v for c, v in enumerate(per_cue)}))  # more than any configuration
    full, cut = _decoded(bus)
    assert full.telemetry == most
    kept = list(cut.telemetry.items())  # whole cues only, the first ones, at least what a configuration logs
    assert len(most) <= len(kept) < len(per_cue)
    assert kept == [(f"cue{c}", v) for c, v in enumerate(per_cue[: len(kept)])]
    assert sink.encode_errors == 0
