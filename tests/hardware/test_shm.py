"""Shared-memory slots, rings, event rows and the cycle-record codec of the real-time process."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lapwrench.hardware.log import CycleRecord
from lapwrench.hardware.rt import MAX_POINTS, CycleCodec, ShmInput, ShmLogSink, bus_layout
from lapwrench.hardware.shm import Bus, Layout, ShmError, pack_event, unpack_event
from lapwrench.robot.description import MAX_JOINTS


@pytest.fixture
def bus():
    b = Bus.create(bus_layout(log_rows=8, event_rows=16))
    try:
        yield b
    finally:
        b.close()


def test_regions_are_aligned_and_shared_between_mappings(bus: Bus) -> None:
    for offset, _dt, _shape in bus.layout.regions.values():
        assert offset % 64 == 0
    other = Bus.attach(bus.name, bus_layout(log_rows=8, event_rows=16))
    try:
        bus["ctl"][3] = 42
        assert other["ctl"][3] == 42
        slot = other.slot("tactile")
        seq = bus.slot("tactile").write(np.arange(64.0), 12.5)
        out = np.empty(64)
        assert slot.read_into(out) == (seq, 12.5, 64)
        assert np.array_equal(out, np.arange(64.0))
    finally:
        other.close()


def test_attach_refuses_a_missing_or_truncated_block(bus: Bus) -> None:
    with pytest.raises(ShmError, match="does not exist"):
        Bus.attach("lapwrench-no-such-block", bus_layout())
    with pytest.raises(ShmError, match="bytes, the layout needs"):
        Bus.attach(bus.name, bus_layout(log_rows=4096))  # a bigger layout than the block holds


def test_seqlock_never_returns_a_torn_or_abandoned_write(bus: Bus) -> None:
    slot = bus.slot("instruments")
    out = np.empty_like(slot.data)
    assert slot.read_into(out) is None  # nothing published yet
    slot.write(np.array([[1.0, 2.0]]), 3.0, count=1)
    _seq, stamp, count = slot.read_into(out)
    assert (stamp, count) == (3.0, 1) and np.array_equal(out[0], [1.0, 2.0])
    slot.hdr[0] += 1  # a writer died in the middle of a write: the sequence stays odd
    assert slot.read_into(out) is None
    # the next writer recovers from the abandoned write
    assert slot.write(np.array([[5.0, 6.0], [7.0, 8.0]]), 4.0, count=2) % 2 == 0
    assert slot.read_into(out)[1:] == (4.0, 2)


def test_ring_drops_and_counts_when_full_never_blocks(bus: Bus) -> None:
    ring = bus.ring("log")
    row = np.zeros(CycleCodec.WIDTH)
    for i in range(10):
        row[0] = i
        ring.push(row)
    assert ring.dropped == 2 and ring.pending() == 8
    got = ring.take(3)
    assert list(got[:, 0]) == [0, 1, 2]
    assert list(ring.take()[:, 0]) == [3, 4, 5, 6, 7] and ring.pending() == 0
    row[0] = 99
    assert ring.push(row)  # room again, wrapped around
    assert ring.take()[0, 0] == 99


def test_event_rows_truncate_long_messages() -> None:
    row = np.zeros(64, np.uint8)
    pack_event(row, 1.5, "peer_hung", "x" * 500)
    t, kind, message = unpack_event(row)
    assert (t, kind) == (1.5, "peer_hung") and message.endswith("...") and len(message) < 64


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


def test_shared_inputs_flag_corrupt_slots(bus: Bus) -> None:
    tac = ShmInput(bus.slot("tactile"), "tactile", clock=lambda: 10.0)
    ins = ShmInput(bus.slot("instruments"), "instruments", clock=lambda: 10.0)
    assert tac.refresh(10.0) is None and tac.get_fresh(0.1, 10.0) is None  # nothing yet: stale
    bus.slot("tactile").write(np.full(64, 40.0), 9.95)
    assert tac.refresh(10.0) is None
    s = tac.get_fresh(0.1, 10.0)
    assert s is not None and s.value.values[0] == 40.0 and s.timestamp == 9.95
    assert tac.get_fresh(0.1, 10.2) is None  # too old
    bad = np.full(64, 40.0)
    bad[5] = math.nan
    bus.slot("tactile").write(bad, 10.0)
    assert "tactile slot" in tac.refresh(10.0) and tac.get_fresh(0.1, 10.0) is None
    bus.slot("instruments").write(np.zeros((1, 2)), 20.0, count=1)  # a stamp from the future
    assert "stamp" in ins.refresh(10.0)
    slot = bus.slot("instruments")
    slot.write(np.zeros((1, 2)), 9.9, count=1)
    slot.hdr[1] = MAX_POINTS + 4  # a count beyond the slot
    assert "point count" in ins.refresh(10.0)


def test_layout_rejects_duplicates() -> None:
    with pytest.raises(ValueError):
        Layout().add("a", np.int64, (1,)).add("a", np.int64, (1,))
