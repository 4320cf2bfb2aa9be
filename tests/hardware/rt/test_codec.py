"""The cycle-record codec and log sink of the real-time process, through the shared-memory rings."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from lapwrench.hardware.log import CycleRecord
from lapwrench.hardware.rt import CycleCodec, ShmLogSink
from lapwrench.hardware.shm import Bus, unpack_event
from lapwrench.robot.description import MAX_JOINTS


def record(**over: Any) -> CycleRecord:
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


def _round_trip(rec: CycleRecord) -> CycleRecord:
    """``rec`` encoded into a row and decoded, the announcements passed on as the parent does."""
    announced: list[str] = []
    encoder, decoder = CycleCodec(lambda table, name: announced.append(f"{table}:{name}") or True), CycleCodec()
    row = np.full(CycleCodec.WIDTH, 7.0)  # a reused ring slot: whatever the last lap left
    encoder.encode(row, rec)
    for message in announced:
        decoder.learn(message)
    return decoder.decode(row)


def test_every_field_of_a_record_survives_the_row() -> None:
    """Each field comes back as it went in, none in another's place (every value differs from the others)."""
    rec = record(
        t=1.5, robot_time=1.25, k=11, tau_J=np.arange(7.0) + 100, rcm_error_measured=3e-3, alarm=True,
        delta=0.75, contacts=12, rcm_error=4e-3, compute_us=250.0, cycle_us=999.0, mode="tracking",
        supervisor="holding", p_R=np.array([0.4, 0.1, 0.2]), q_ref=np.arange(7.0) + 10, q_cmd=np.arange(7.0) + 20,
        telemetry={"zoom": (0.5, 1.0, 0.0)},
    )
    got = _round_trip(rec)
    for name in ("t", "robot_time", "k", "mode", "delta", "contacts", "rcm_error", "rcm_error_measured", "supervisor",
                 "alarm", "compute_us", "cycle_us", "telemetry"):
        assert getattr(got, name) == getattr(rec, name), name
    for name in ("q", "dq", "tau_J", "external_force", "ft_torque", "tactile", "instruments", "p_R", "e_R", "q_ref",
                 "q_cmd"):
        assert np.array_equal(getattr(got, name), getattr(rec, name)), name
    assert np.array_equal(got.ft_force, rec.ft_force, equal_nan=True)
    assert {k: v.tolist() for k, v in got.wrenches.items()} == {k: v.tolist() for k, v in rec.wrenches.items()}


class _CountingRow(np.ndarray):
    """A row that counts numpy's item assignments into it."""

    assignments = 0

    def __setitem__(self, key: object, value: object) -> None:
        type(self).assignments += 1
        super().__setitem__(key, value)


def test_the_loops_float_arrays_are_copied_as_they_are() -> None:
    """A record of float64 arrays (the loop's) is written without numpy's per-item conversion: every value
    reaches the row as it is (the 1 kHz child's cost; anything else is converted, as the next test shows)."""
    row = np.zeros(CycleCodec.WIDTH).view(_CountingRow)
    codec = CycleCodec(lambda table, name: True)
    codec.encode(row, record(tau_J=np.ones(7), rcm_error_measured=1e-3, telemetry={"zoom": (0.5, 1.0, 0.0)}))
    codec.encode(row, record(tactile=None, instruments=None, external_force=None))
    assert _CountingRow.assignments == 0
    decoder = CycleCodec()
    for table, names in codec.tables.items():
        for name in names:
            decoder.learn(f"{table}:{name}")
    assert decoder.decode(np.asarray(row)).tactile is None


def test_other_values_reach_the_row_as_numpy_converts_them() -> None:
    """Lists, integers, float32, strided views, other byte orders, shapes numpy broadcasts, ``None`` or a
    numeric string in a plain value: the row holds what ``numpy`` makes of them, as before; what numpy
    refuses is a record that does not encode."""
    strided = np.arange(14.0)[::2]
    rec = record(
        q=list(range(7)), dq=strided, tau_J=np.arange(7, dtype=np.int32), external_force=np.arange(3.0).astype(">f8"),
        ft_torque=np.ones(3, np.float32) / 3, tactile=[2.0] * 64, p_R=0.5, e_R=np.ones((1, 3)), q_cmd=np.array([1.5]),
        instruments=np.asfortranarray([[1.0, 2.0], [3.0, 4.0]]), wrenches={"rcm": [1, 2, 3, 4, 5, 6]},
        delta=None, contacts=np.int64(3), compute_us="12.5", telemetry={"zoom": np.array([1.0, 2.0]), "x": [None]},
    )
    got = _round_trip(rec)
    assert got.q.tolist() == got.tau_J.tolist() == list(range(7)) and got.dq.tolist() == strided.tolist()
    assert got.external_force.tolist() == [0.0, 1.0, 2.0] and got.ft_torque.tolist() == [np.float32(1 / 3)] * 3
    assert got.tactile.tolist() == [2.0] * 64 and got.p_R.tolist() == [0.5] * 3 and got.e_R.tolist() == [1.0] * 3
    assert got.q_cmd.tolist() == [1.5] * 7 and got.instruments.tolist() == [[1.0, 2.0], [3.0, 4.0]]
    assert got.wrenches["rcm"].tolist() == [1, 2, 3, 4, 5, 6]
    assert np.isnan(got.delta) and got.contacts == 3 and got.compute_us == 12.5
    assert got.telemetry["zoom"] == (1.0, 2.0) and np.isnan(got.telemetry["x"][0])
    for bad in ({"e_R": np.ones((3, 1))}, {"dq": np.ones(6)}, {"delta": 1j}, {"wrenches": {"rcm": np.ones(5)}},
                {"instruments": np.arange(3.0)}, {"telemetry": {"zoom": ((1.0, 2.0),)}}):
        with pytest.raises((ValueError, TypeError)):
            _round_trip(record(**bad))
