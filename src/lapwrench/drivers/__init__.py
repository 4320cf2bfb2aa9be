"""Sensor drivers for the laparoscope-holding robot (paper Sec. II-A hardware).

Every source runs a background reader thread and publishes into a non-blocking latest-value buffer
(:class:`LatestValue`) stamped with ``time.monotonic()``; the 1 kHz control loop only peeks at the
newest :class:`Sample` and switches a source's wrench off when ``fresh(max_age)`` is False.

* :mod:`~lapwrench.buffer` (re-exported here): :class:`LatestValue`, :class:`Sample`, :class:`RateMonitor`.
* :mod:`~lapwrench.drivers.base`: :class:`StreamingSource` life cycle and the error types.
* :mod:`~lapwrench.drivers.ft`: OnRobot HEX (compute box, EtherDAQ UDP) and ATI Net F/T (RDT UDP).
* :mod:`~lapwrench.drivers.tactile`: 64-element tactile array over serial (pyserial).
* :mod:`~lapwrench.drivers.camera`: laparoscope camera through OpenCV ``VideoCapture``.
* :mod:`~lapwrench.drivers.simulated_hex`: a simulated HEX box on loopback UDP for dry runs and tests.

Typical use (one source shown)::

    ft = OnRobotHexSensor("192.168.1.1").start()  # raises DeviceOpenError/DeviceTimeoutError
    ft.tare(n_samples=200)                         # handle untouched
    ...
    # in the 1 kHz loop: never blocks
    s = ft.buffer.get_fresh(max_age=0.01)
    wrench = None if s is None else s.value        # None -> that wrench is switched off
    ...
    ft.stop()

The camera module (OpenCV) and the simulated HEX box are imported lazily on first attribute access,
so ``import lapwrench.drivers`` stays light for code that only needs the F/T or tactile readers.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from lapwrench.buffer import LatestValue, RateMonitor, RateStats, Sample
from lapwrench.drivers.base import (
    DeviceError,
    DeviceOpenError,
    DeviceTimeoutError,
    EndOfStream,
    PacketError,
    SourceStatus,
    StreamingSource,
)
from lapwrench.drivers.ft import (
    AtiNetFTSensor,
    OnRobotHexSensor,
    StatusError,
    UdpForceTorqueSensor,
    Wrench,
)
from lapwrench.drivers.tactile import (
    ChecksumType,
    SerialTactileArray,
    TactileFrame,
    TactileFrameFormat,
    TactileFrameParser,
)

if TYPE_CHECKING:
    from lapwrench.drivers.camera import Camera, CameraFrame
    from lapwrench.drivers.simulated_hex import SimulatedHexBox

__all__ = [
    "AtiNetFTSensor",
    "Camera",
    "CameraFrame",
    "ChecksumType",
    "DeviceError",
    "DeviceOpenError",
    "DeviceTimeoutError",
    "EndOfStream",
    "LatestValue",
    "OnRobotHexSensor",
    "PacketError",
    "RateMonitor",
    "RateStats",
    "Sample",
    "SerialTactileArray",
    "SimulatedHexBox",
    "SourceStatus",
    "StatusError",
    "StreamingSource",
    "TactileFrame",
    "TactileFrameFormat",
    "TactileFrameParser",
    "UdpForceTorqueSensor",
    "Wrench",
]

_LAZY = {
    "Camera": "lapwrench.drivers.camera",
    "CameraFrame": "lapwrench.drivers.camera",
    "SimulatedHexBox": "lapwrench.drivers.simulated_hex",
}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value
