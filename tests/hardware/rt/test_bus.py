"""lapwrench.hardware.rt.bus: the real-time bus's layout, the same in every process."""

from __future__ import annotations

from lapwrench.hardware.rt.bus import bus_layout, input_slot
from lapwrench.hardware.shm import Bus


def test_every_process_builds_the_same_layout() -> None:
    a, b = bus_layout(16, 8, (("pedal", (1,)),)), bus_layout(16, 8, (("pedal", (1,)),))
    assert a.size == b.size


def test_the_rings_and_slots_are_where_the_processes_look() -> None:
    bus = Bus.create(bus_layout(16, 8, (("pedal", (3,)),)))
    try:
        assert bus["ctl"].shape == (16,) and bus["beat"].shape == (8,)
        assert bus.slot(input_slot("pedal")).data.shape == (3,)
        assert bus.slot("tactile").data.shape == (64,)
        assert bus.ring("log") is not None and bus.ring("events") is not None
    finally:
        bus.close()


def test_registered_input_slots_are_named_apart_from_the_fixed_ones() -> None:
    assert input_slot("tactile") != "tactile" and input_slot("pedal") == "input:pedal"
