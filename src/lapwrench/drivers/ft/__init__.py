"""6-axis force/torque sensors streaming over UDP: OnRobot HEX (compute box) and ATI Net F/T RDT.

Both devices speak the same 0x1234 RDT/EtherDAQ protocol on UDP port 49152. The package, by job:

* :mod:`~lapwrench.drivers.ft.wire`: the protocol (requests, 36-byte records, :data:`WIRE_ORDER`,
  :class:`Wrench`, :func:`wire_counts`) and the public drivers it follows.
* :mod:`~lapwrench.drivers.ft.stream`: the socket and reader thread, record checks (status word,
  plausibility, sequence via :class:`~lapwrench.buffer.RateMonitor`) and the software bias.
* :mod:`~lapwrench.drivers.ft.sensor`: :class:`UdpForceTorqueSensor`, adding polled mode (no
  thread) and tare.
* :mod:`~lapwrench.drivers.ft.onrobot`: :class:`OnRobotHexSensor`.
* :mod:`~lapwrench.drivers.ft.ati`: :class:`AtiNetFTSensor`.

Nothing leaves the driver in the record's ``[Fx, Fy, Fz, Tx, Ty, Tz]`` order: each accepted record
is published as a :class:`Wrench` (force (3,) N, torque (3,) N·m, sensor frame, bias removed).
"""

from __future__ import annotations

from lapwrench.drivers.ft.ati import AtiNetFTSensor
from lapwrench.drivers.ft.onrobot import OnRobotHexSensor
from lapwrench.drivers.ft.sensor import UdpForceTorqueSensor
from lapwrench.drivers.ft.wire import (
    CMD_BIAS,
    CMD_SET_FILTER,
    CMD_SET_SPEED,
    CMD_START_REALTIME,
    CMD_STOP,
    DEFAULT_PORT,
    RDT_HEADER,
    RECORD_SIZE,
    REQUEST_SIZE,
    WIRE_ORDER,
    FTRecord,
    StatusError,
    Wrench,
    pack_record,
    pack_request,
    record_fields,
    unpack_record,
    unpack_request,
    wire_counts,
)

__all__ = [
    "CMD_BIAS",
    "CMD_SET_FILTER",
    "CMD_SET_SPEED",
    "CMD_START_REALTIME",
    "CMD_STOP",
    "DEFAULT_PORT",
    "RDT_HEADER",
    "RECORD_SIZE",
    "REQUEST_SIZE",
    "WIRE_ORDER",
    "AtiNetFTSensor",
    "FTRecord",
    "OnRobotHexSensor",
    "StatusError",
    "UdpForceTorqueSensor",
    "Wrench",
    "pack_record",
    "pack_request",
    "record_fields",
    "unpack_record",
    "unpack_request",
    "wire_counts",
]
