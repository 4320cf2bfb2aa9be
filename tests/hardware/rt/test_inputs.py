"""The shared-memory inputs of the real-time process flag corrupt slots."""

from __future__ import annotations

import math

import numpy as np

from lapwrench.hardware.rt import MAX_POINTS, ShmInput
from lapwrench.hardware.shm import Bus, SeqlockSlot


class CountingSlot(SeqlockSlot):
    """A slot that counts the copies of its payload."""

    copies = 0

    def read_into(self, out: np.ndarray, retries: int = 4) -> tuple[int, float, int] | None:
        type(self).copies += 1
        return super().read_into(out, retries)


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


def test_a_registered_input_reads_its_own_slot_as_an_array() -> None:
    from lapwrench.hardware.rt.bus import bus_layout, input_slot

    b = Bus.create(bus_layout(log_rows=8, event_rows=16, inputs=(("pedal", (2,)), ("grid", (2, 3)))))
    try:
        pedal = ShmInput(b.slot(input_slot("pedal")), "pedal", clock=lambda: 10.0, registered=True)
        b.slot(input_slot("pedal")).write(np.array([0.25, 1.0]), 9.99)
        assert pedal.refresh(10.0) is None
        s = pedal.get_fresh(0.1, 10.0)
        assert s is not None and s.value.tolist() == [0.25, 1.0] and s.timestamp == 9.99
        b.slot(input_slot("pedal")).write(np.zeros(1), 10.0, count=1)  # fewer rows than its shape
        assert "1 rows, not 2" in pedal.refresh(10.0)
        grid = ShmInput(b.slot(input_slot("grid")), "grid", clock=lambda: 10.0, registered=True)
        b.slot(input_slot("grid")).write(np.arange(6.0).reshape(2, 3), 9.99)  # a 2-D reading, whole
        assert grid.refresh(10.0) is None and grid.get().value.shape == (2, 3)  # type: ignore[union-attr]
    finally:
        b.close()


def test_the_input_slots_come_after_the_fixed_regions() -> None:
    """A process that needs only the fixed regions (the detector) attaches with the shorter layout."""
    from lapwrench.hardware.rt.bus import bus_layout

    short, long = bus_layout(8, 16), bus_layout(8, 16, (("pedal", (1,)),))
    assert long.size > short.size
    b = Bus.create(long)
    try:
        assert Bus.attach(b.shm.name, short)["ctl"].shape == (16,)
    finally:
        b.close()


def test_an_unchanged_slot_is_not_copied_again_and_a_torn_one_is_still_counted(bus: Bus) -> None:
    """The child refreshes every input after every command, and a writer publishes at 25 to 200 Hz: a refresh
    that finds the sequence number it has read copies nothing. A write in progress (odd number) is read,
    retried and counted torn as before."""
    plain = bus.slot("tactile")
    slot = CountingSlot(plain.hdr, plain.stamp, plain.data)
    tac = ShmInput(slot, "tactile", clock=lambda: 10.0)
    assert tac.refresh(10.0) is None and CountingSlot.copies == 0  # nothing published yet: nothing to copy
    plain.write(np.full(64, 40.0), 9.95)
    assert tac.refresh(10.0) is None and CountingSlot.copies == 1
    for _ in range(5):
        assert tac.refresh(10.0) is None
    assert CountingSlot.copies == 1  # unchanged: not copied again
    s = tac.get_fresh(0.1, 10.0)
    assert s is not None and s.value.values[0] == 40.0
    plain.write(np.full(64, 41.0), 9.99)
    assert tac.refresh(10.0) is None and CountingSlot.copies == 2 and tac.get().value.values[0] == 41.0  # type: ignore[union-attr]
    plain.hdr[0] += 1  # a writer stopped in the middle of a write
    assert tac.refresh(10.0) is None and tac.refresh(10.0) is None
    assert tac.torn == 2 and tac.get().value.values[0] == 41.0  # type: ignore[union-attr]
