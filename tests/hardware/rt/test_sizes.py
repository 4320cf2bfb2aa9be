"""lapwrench.hardware.rt.sizes: the fixed sizes of the bus's slots and rings hold what travels in them
(the codec, the feeders and the detector all size their data by them; an event of useful length)."""

from __future__ import annotations

import numpy as np

from lapwrench.hardware.rt.bus import bus_layout
from lapwrench.hardware.rt.sizes import EVENT_BYTES, MAX_POINTS, TACTILE_N
from lapwrench.hardware.shm import Bus, pack_event, unpack_event


def test_the_slots_are_the_sizes_the_codec_and_the_feeders_use() -> None:
    bus = Bus.create(bus_layout(8, 4))
    try:
        assert bus.slot("tactile").data.shape == (TACTILE_N,)
        assert bus.slot("instruments").data.shape == (MAX_POINTS, 2)
        assert bus.ring("events").rows.shape[1] == EVENT_BYTES
    finally:
        bus.close()


def test_an_event_row_carries_a_full_supervisor_message() -> None:
    row = np.zeros(EVENT_BYTES, np.uint8)
    message = "RCM error 12.3 mm at the measured joints (limit 8.0 mm); stopping to rest within the limits"
    pack_event(row, 1.25, "rcm_error", message)
    assert unpack_event(row) == (1.25, "rcm_error", message)

