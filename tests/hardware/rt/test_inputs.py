"""The shared-memory inputs of the real-time process flag corrupt slots."""

from __future__ import annotations

import math

import numpy as np

from lapwrench.hardware.rt import MAX_POINTS, ShmInput
from lapwrench.hardware.shm import Bus


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
