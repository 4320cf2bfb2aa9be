"""The shared-memory bus of the real-time process: its sizes, control words, heartbeat stamps,
phases and :func:`bus_layout` (every process builds the same layout). The slot sizes are
:mod:`lapwrench.hardware.rt.sizes`' (the cycle codec needs them too) and are re-exported here."""

from __future__ import annotations

import numpy as np

from lapwrench.hardware.rt.codec import CycleCodec
from lapwrench.hardware.rt.sizes import EVENT_BYTES, MAX_POINTS, TACTILE_N
from lapwrench.hardware.shm import Layout

# control words (int64) and heartbeat stamps (float64) on the bus
CTL_STOP, CTL_PHASE, CTL_CYCLES, CTL_DET_STOP, CTL_DET_FRAMES, CTL_DET_ERRORS = 0, 1, 2, 3, 4, 5
BEAT_PARENT, BEAT_CHILD, BEAT_DETECTOR = 0, 1, 2
PHASE_STARTING, PHASE_READY, PHASE_RUNNING, PHASE_DONE = 0, 1, 2, 3


def bus_layout(
    log_rows: int = 4096, event_rows: int = 1024, inputs: tuple[tuple[str, tuple[int, ...]], ...] = ()
) -> Layout:
    """The regions of the real-time bus (every process builds the same layout), with one slot
    ``input:<name>`` per registered input the cues ask for (:mod:`lapwrench.inputs`), after the
    fixed regions: a process that needs only those (the detector) attaches with ``inputs=()``."""
    layout = (
        Layout()
        .add("ctl", np.int64, (16,))
        .add("beat", np.float64, (8,))
        .slot("tactile", np.float64, (TACTILE_N,))
        .slot("instruments", np.float64, (MAX_POINTS, 2))
        .ring("log", np.float64, log_rows, CycleCodec.WIDTH)
        .ring("events", np.uint8, event_rows, EVENT_BYTES)
    )
    for name, shape in inputs:
        layout = layout.slot(input_slot(name), np.float64, shape)
    return layout


def input_slot(name: str) -> str:
    """The bus slot of registered input ``name``."""
    return f"input:{name}"
