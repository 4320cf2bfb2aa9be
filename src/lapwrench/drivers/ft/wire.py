"""The RDT/EtherDAQ wire format of the UDP F/T sensors: requests, records and their scaling.

Protocol (both devices, UDP port 49152 on the device, all fields big-endian)
---------------------------------------------------------------------------
Request, host -> device, 8 bytes::

    uint16 header = 0x1234
    uint16 command          0x0000 stop streaming
                            0x0002 start high-speed real-time streaming
                            0x0042 set software bias (tare inside the device)
                            0x0081 set filter (HEX/EtherDAQ only)
                            0x0082 set speed  (HEX/EtherDAQ only)
    uint32 sample_count     0 = stream forever; data word for 0x0042/0x0081/0x0082

Record, device -> host, 36 bytes (one per datagram in real-time mode)::

    uint32 sequence         RDT sequence (ATI) / high-speed sequence (HEX); +1 per datagram
    uint32 ft_sequence      the device's internal sample counter
    uint32 status           0 = OK; any other value is a device status/error word
    int32  Fx, Fy, Fz, Tx, Ty, Tz   raw counts

Sources followed (public drivers, consulted through the code index):

* ``ros-drivers/ati_netft_ros_driver`` (``netft_rdt_driver/src/netft_rdt_driver.cpp``): RDT
  request/record layout, header 0x1234, command 2, 36-byte records, sequence-gap drop counting and
  discarding of out-of-order records. It hard-codes 1e6 counts/N and 1e9 counts/Nm.
* ``sssa-human-robot-interaction-lab/onrobot_etherdaq_driver`` (OnRobot HEX / EtherDAQ ROS node):
  same 8-byte request (``htonl`` for the 32-bit word), commands 0x0000/0x0002/0x0042 (bias data
  0xFF on / 0x00 off)/0x0081 filter/0x0082 speed, 36-byte response, and the default scaling
  ``FORCE_DIV = 10000`` counts/N and ``TORQUE_DIV = 100000`` counts/Nm.
* ``ipa-rwu/etherdaq_ros2`` (OptoForce EtherDAQ driver): the HSU record
  (hs_sequence, ft_sequence, status, Fx..Tz); speed word = 1000 / rate_Hz.

Note: several of these C++ drivers pack the 32-bit ``sample_count`` by writing its low 16 bits
twice; that is harmless for 0 (stream forever) but wrong in general. We pack a true uint32.

Inside the driver the six values travel in the record's order, :data:`WIRE_ORDER`
``[Fx, Fy, Fz, Tx, Ty, Tz]`` (force first, unlike lapwrench's ``[moment; force]`` wrenches of
:mod:`lapwrench.spatial`). Nothing leaves the driver in that order: each accepted record is
published as a :class:`Wrench` with named parts. Malformed datagrams raise
:class:`~lapwrench.drivers.base.PacketError`.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lapwrench.drivers.base import PacketError

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
    "FTRecord",
    "StatusError",
    "Wrench",
    "named_wrench",
    "pack_record",
    "pack_request",
    "record_fields",
    "unpack_record",
    "unpack_request",
    "wire_counts",
]

DEFAULT_PORT = 49152
RDT_HEADER = 0x1234
CMD_STOP = 0x0000
CMD_START_REALTIME = 0x0002
CMD_BIAS = 0x0042
CMD_SET_FILTER = 0x0081
CMD_SET_SPEED = 0x0082

WIRE_ORDER: tuple[str, ...] = ("Fx", "Fy", "Fz", "Tx", "Ty", "Tz")
"""Order of the six values of a record (force, then torque) and of this module's internal 6-arrays
(scale, bias, tare samples). Only named force/torque pairs (:class:`Wrench`) leave the driver."""

_REQUEST = struct.Struct(">HHI")
_RECORD = struct.Struct(">III6i")
REQUEST_SIZE = _REQUEST.size  # 8
RECORD_SIZE = _RECORD.size  # 36


class StatusError(PacketError):
    """A well-formed record whose status word flags a device error; the record is discarded."""


@dataclass(frozen=True, slots=True)
class FTRecord:
    """One decoded 36-byte record (raw counts)."""

    sequence: int
    ft_sequence: int
    status: int
    counts: tuple[int, int, int, int, int, int]


@dataclass(frozen=True, slots=True)
class Wrench:
    """A force/torque measurement in the sensor frame, bias removed (or a bias, :meth:`UdpForceTorqueSensor.tare`).

    Attributes:
        force: (3,) N, read-only.
        torque: (3,) N·m, read-only.
        ft_sequence: The device's internal sample counter for this record.
        status: The device status word (always 0 for published samples with the default mask).
    """

    force: NDArray[np.float64]
    torque: NDArray[np.float64]
    ft_sequence: int = 0
    status: int = 0


def named_wrench(w: NDArray[np.float64]) -> Wrench:
    """A (6,) array in :data:`WIRE_ORDER` as a :class:`Wrench` (views of ``w``)."""
    return Wrench(w[:3], w[3:])


def wire_counts(
    force: ArrayLike, torque: ArrayLike = (0.0, 0.0, 0.0), *, counts_per_force: float, counts_per_torque: float
) -> NDArray[np.float64]:
    """The six raw counts (rounded, :data:`WIRE_ORDER`) a device sends for ``force`` (N) and
    ``torque`` (N·m): what a simulated device streams (e.g.
    :class:`~lapwrench.drivers.simulated_hex.SimulatedHexBox`)."""
    f = np.asarray(force, dtype=np.float64).reshape(3) * counts_per_force
    m = np.asarray(torque, dtype=np.float64).reshape(3) * counts_per_torque
    return np.concatenate((f, m)).round()


def pack_request(command: int, sample_count: int = 0, header: int = RDT_HEADER) -> bytes:
    """Encode an 8-byte RDT/EtherDAQ request."""
    return _REQUEST.pack(header, command, sample_count)


def unpack_request(data: bytes) -> tuple[int, int, int]:
    """Decode an 8-byte request into ``(header, command, sample_count)``.

    Raises:
        PacketError: wrong length or header (used by the fake devices and tests).
    """
    if len(data) != REQUEST_SIZE:
        raise PacketError(f"request of {len(data)} bytes, expected {REQUEST_SIZE}")
    header, command, count = _REQUEST.unpack(data)
    if header != RDT_HEADER:
        raise PacketError(f"request header 0x{header:04x}, expected 0x{RDT_HEADER:04x}")
    return header, command, count


def pack_record(sequence: int, ft_sequence: int, status: int, counts: ArrayLike) -> bytes:
    """Encode a 36-byte record from six integer counts (used by fake devices and tests)."""
    c = [int(v) for v in np.asarray(counts).reshape(6)]
    return _RECORD.pack(sequence & 0xFFFFFFFF, ft_sequence & 0xFFFFFFFF, status & 0xFFFFFFFF, *c)


def record_fields(data: bytes) -> tuple[int, ...]:
    """The nine fields of one 36-byte record as they are on the wire: ``(sequence, ft_sequence, status,
    Fx, Fy, Fz, Tx, Ty, Tz)`` (raw counts). What the polled F/T drain decodes each cycle: no
    :class:`FTRecord` built for a record that is checked and, unless it is the newest, dropped.

    Raises:
        PacketError: the datagram is not exactly 36 bytes, or it starts with the request header
            and is 8 bytes long (a command echoed back / sent to the wrong port).
    """
    n = len(data)
    if n != RECORD_SIZE:
        if n == REQUEST_SIZE and data[:2] == RDT_HEADER.to_bytes(2, "big"):
            raise PacketError("received a request packet (header 0x1234) where a record was expected")
        raise PacketError(f"record of {n} bytes, expected {RECORD_SIZE}")
    return _RECORD_UNPACK(data)


_RECORD_UNPACK = _RECORD.unpack


def unpack_record(data: bytes) -> FTRecord:
    """Decode one 36-byte record.

    Raises:
        PacketError: as :func:`record_fields`.
    """
    seq, ft_seq, status, c0, c1, c2, c3, c4, c5 = record_fields(data)
    return FTRecord(seq, ft_seq, status, (c0, c1, c2, c3, c4, c5))
