"""Shared-memory slots, rings, event rows and layouts."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.hardware.rt import CycleCodec, bus_layout
from lapwrench.hardware.shm import Bus, Layout, ShmError, pack_event, unpack_event


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


def test_layout_rejects_duplicates() -> None:
    with pytest.raises(ValueError):
        Layout().add("a", np.int64, (1,)).add("a", np.int64, (1,))
