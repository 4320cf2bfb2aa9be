"""Compatibility module: the real-time process now lives in the package :mod:`lapwrench.hardware.rt`
(one module per job; its docstring describes the process layout and what happens on each fault).

Every public name this module used to define is re-exported here, so old import paths keep working."""

from __future__ import annotations

from lapwrench.hardware.rt.bus import (
    BEAT_CHILD,
    BEAT_DETECTOR,
    BEAT_PARENT,
    CTL_CYCLES,
    CTL_DET_ERRORS,
    CTL_DET_FRAMES,
    CTL_DET_STOP,
    CTL_PHASE,
    CTL_STOP,
    EVENT_BYTES,
    MAX_POINTS,
    PHASE_DONE,
    PHASE_READY,
    PHASE_RUNNING,
    PHASE_STARTING,
    TACTILE_N,
    bus_layout,
)
from lapwrench.hardware.rt.codec import (
    INTERN,
    CycleCodec,
    ShmLogSink,
)
from lapwrench.hardware.rt.factories import (
    franka_factory,
    sim_factory,
)
from lapwrench.hardware.rt.inputs import (
    ShmInput,
)
from lapwrench.hardware.rt.options import (
    RtOptions,
    apply_realtime,
)
from lapwrench.hardware.rt.parent import (
    RtProcess,
)
from lapwrench.hardware.rt.peers import (
    PeerSpec,
    PeerWatch,
)
from lapwrench.hardware.rt.spec import (
    FtSpec,
    RtProcessError,
    RtResult,
    RtSpec,
)

__all__ = [
    "BEAT_CHILD",
    "BEAT_DETECTOR",
    "BEAT_PARENT",
    "CTL_CYCLES",
    "CTL_DET_ERRORS",
    "CTL_DET_FRAMES",
    "CTL_DET_STOP",
    "CTL_PHASE",
    "CTL_STOP",
    "EVENT_BYTES",
    "INTERN",
    "MAX_POINTS",
    "PHASE_DONE",
    "PHASE_READY",
    "PHASE_RUNNING",
    "PHASE_STARTING",
    "TACTILE_N",
    "CycleCodec",
    "FtSpec",
    "PeerSpec",
    "PeerWatch",
    "RtOptions",
    "RtProcess",
    "RtProcessError",
    "RtResult",
    "RtSpec",
    "ShmInput",
    "ShmLogSink",
    "apply_realtime",
    "bus_layout",
    "franka_factory",
    "sim_factory",
]
