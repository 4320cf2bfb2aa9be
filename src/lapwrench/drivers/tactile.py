"""64-element tactile (grip) array on a serial line, read with pyserial.

The paper's handle carries a flexible 64-element array (Zhongke Benyuan); each element reads 0
without contact and (0, 255] under load (Sec. II-A). Its wire format is not published, so the frame
layout is configurable with :class:`TactileFrameFormat`::

    header (>= 1 byte, e.g. AA 55) | [length: uint8] | payload | [checksum]

* ``payload``: ``n_elements`` values of ``element_width`` bytes (1 by default; 2 = uint16 in
  ``byteorder``), values above ``max_value`` are rejected.
* ``length`` (optional): number of payload bytes; a mismatch rejects the frame.
* ``checksum`` over the length byte and payload (plus the header if
  ``checksum_includes_header``): ``none``, ``sum8`` (byte sum mod 256), ``xor8`` (XOR of bytes),
  or ``crc16-modbus`` (poly 0xA001 reflected, init 0xFFFF, sent low byte first).

Resynchronisation: :class:`TactileFrameParser` scans for the header, skips anything before it
(counted as garbage), and on a rejected candidate frame drops only its first byte and scans again,
so a real header inside a corrupted or truncated frame is found. A frame cut short on the wire is
only detectable with a checksum. Without one, a frame counts only once the next frame's header
follows it exactly where it should (one frame of latency): random bytes or line noise then practically
never pass as a frame (a header at two exact places), and a frame cut short is rejected. A grip must
never come from corruption. Use a checksum for the real device if it offers one.

:class:`SerialTactileArray` runs the parser in a reader thread and publishes
:class:`TactileFrame` values (read-only ``values`` array) into a latest-value buffer. The port may
be a device path (``/dev/ttyUSB0``), a pty, or any pyserial URL (``loop://``, ``socket://``...).
"""

from __future__ import annotations

import contextlib
import time
from dataclasses import dataclass, field
from enum import StrEnum
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lapwrench.drivers.base import DeviceOpenError, PacketError, StreamingSource

if TYPE_CHECKING:
    import serial

__all__ = [
    "ChecksumType",
    "SerialTactileArray",
    "TactileFrame",
    "TactileFrameFormat",
    "TactileFrameParser",
    "crc16_modbus",
]


class ChecksumType(StrEnum):
    """Frame checksum algorithms."""

    NONE = "none"
    SUM8 = "sum8"
    XOR8 = "xor8"
    CRC16_MODBUS = "crc16-modbus"


def _crc16_modbus_table() -> list[int]:
    table = []
    for i in range(256):
        crc = i
        for _ in range(8):
            crc = (crc >> 1) ^ 0xA001 if crc & 1 else crc >> 1
        table.append(crc)
    return table


_CRC_TABLE = _crc16_modbus_table()


def crc16_modbus(data: bytes | bytearray | memoryview) -> int:
    """CRC-16/MODBUS of ``data`` (check value for b"123456789" is 0x4B37)."""
    crc = 0xFFFF
    for b in bytes(data):
        crc = (crc >> 8) ^ _CRC_TABLE[(crc ^ b) & 0xFF]
    return crc


@dataclass(frozen=True, slots=True)
class TactileFrameFormat:
    """Wire format of one tactile frame (see the module docstring)."""

    header: bytes = b"\xaa\x55"
    n_elements: int = 64
    element_width: Literal[1, 2] = 1
    byteorder: Literal["little", "big"] = "little"
    length_byte: bool = False
    checksum: ChecksumType = ChecksumType.NONE
    checksum_includes_header: bool = False
    max_value: int = 255

    def __post_init__(self) -> None:
        if not self.header:
            raise ValueError("header must be at least one byte")
        if self.n_elements < 1:
            raise ValueError("n_elements must be >= 1")
        if self.element_width not in (1, 2):
            raise ValueError("element_width must be 1 or 2")
        if self.length_byte and self.payload_size > 255:
            raise ValueError("payload too long for a one-byte length field")
        if not 0 < self.max_value < 256**self.element_width:
            raise ValueError("max_value does not fit element_width")
        object.__setattr__(self, "checksum", ChecksumType(self.checksum))

    @property
    def payload_size(self) -> int:
        """Payload bytes per frame."""
        return self.n_elements * self.element_width

    @property
    def checksum_size(self) -> int:
        """Checksum bytes per frame."""
        return {ChecksumType.NONE: 0, ChecksumType.SUM8: 1, ChecksumType.XOR8: 1}.get(self.checksum, 2)

    @property
    def frame_size(self) -> int:
        """Total bytes per frame."""
        return len(self.header) + int(self.length_byte) + self.payload_size + self.checksum_size

    @property
    def dtype(self) -> np.dtype:
        """NumPy dtype of the decoded values."""
        if self.element_width == 1:
            return np.dtype(np.uint8)
        return np.dtype("<u2" if self.byteorder == "little" else ">u2")

    def compute_checksum(self, covered: bytes | bytearray | memoryview) -> bytes:
        """Checksum bytes for the covered region."""
        c = self.checksum
        if c is ChecksumType.NONE:
            return b""
        if c is ChecksumType.SUM8:
            return bytes([sum(bytes(covered)) & 0xFF])
        if c is ChecksumType.XOR8:
            x = 0
            for b in bytes(covered):
                x ^= b
            return bytes([x])
        return crc16_modbus(covered).to_bytes(2, "little")

    def encode(self, values: ArrayLike) -> bytes:
        """Build one frame from ``n_elements`` values (for simulators and tests)."""
        v = np.asarray(values).reshape(-1)
        if v.size != self.n_elements:
            raise ValueError(f"expected {self.n_elements} values, got {v.size}")
        if np.any(v < 0) or np.any(v > self.max_value):
            raise ValueError("values out of range")
        payload = v.astype(self.dtype).tobytes()
        body = (bytes([len(payload)]) if self.length_byte else b"") + payload
        covered = (self.header + body) if self.checksum_includes_header else body
        return self.header + body + self.compute_checksum(covered)

    def decode(self, frame: bytes | bytearray | memoryview) -> NDArray[np.integer]:
        """Validate one complete frame (header at offset 0) and return its values.

        Raises:
            PacketError: wrong size, header, length byte, checksum or value range.
        """
        f = bytes(frame)
        if len(f) != self.frame_size:
            raise PacketError(f"frame of {len(f)} bytes, expected {self.frame_size}")
        h = len(self.header)
        if f[:h] != self.header:
            raise PacketError("bad frame header")
        pos = h
        if self.length_byte:
            if f[pos] != self.payload_size:
                raise PacketError(f"length byte {f[pos]} != payload size {self.payload_size}")
            pos += 1
        payload = f[pos : pos + self.payload_size]
        if self.checksum is not ChecksumType.NONE:
            covered = f[: pos + self.payload_size] if self.checksum_includes_header else f[h : pos + self.payload_size]
            got = f[pos + self.payload_size :]
            want = self.compute_checksum(covered)
            if got != want:
                raise PacketError(f"{self.checksum.value} checksum mismatch: got {got.hex()}, want {want.hex()}")
        values = np.frombuffer(payload, dtype=self.dtype).astype(self.dtype.newbyteorder("="))
        if int(values.max()) > self.max_value:  # 1-byte elements too: a format may cap them below 255
            raise PacketError(f"element value {int(values.max())} > max_value {self.max_value}")
        return values


@dataclass(slots=True)
class TactileFrameParser:
    """Incremental, resynchronising frame parser (not thread-safe; one reader thread).

    Attributes:
        frames: Valid frames decoded.
        malformed: Candidate frames rejected (checksum, length byte, value range).
        garbage_bytes: Bytes skipped while searching for a header.
    """

    fmt: TactileFrameFormat
    max_buffer: int = 65536
    frames: int = 0
    malformed: int = 0
    garbage_bytes: int = 0
    _buf: bytearray = field(default_factory=bytearray)

    def feed(self, data: bytes | bytearray) -> tuple[list[NDArray[np.integer]], list[PacketError]]:
        """Consume ``data``; return the complete valid frames and the errors for rejected ones."""
        buf = self._buf
        buf.extend(data)
        frames: list[NDArray[np.integer]] = []
        errors: list[PacketError] = []
        header = self.fmt.header
        size = self.fmt.frame_size
        while True:
            idx = buf.find(header)
            if idx < 0:
                keep = len(header) - 1  # a header may straddle two reads
                drop = max(0, len(buf) - keep)
                self.garbage_bytes += drop
                del buf[:drop]
                break
            if idx > 0:
                self.garbage_bytes += idx
                del buf[:idx]
            confirm = len(header) if self.fmt.checksum is ChecksumType.NONE else 0
            if len(buf) < size + confirm:
                break
            try:
                values = self.fmt.decode(buf[:size])
                if confirm and buf[size : size + confirm] != header:
                    raise PacketError("frame not followed by the next header: unconfirmed (the format has no checksum)")
            except PacketError as exc:
                self.malformed += 1
                errors.append(exc)
                del buf[:1]  # resync: look for the next header after this byte
                continue
            frames.append(values)
            self.frames += 1
            del buf[:size]
        if len(buf) > self.max_buffer:  # cannot happen with a sane format; bound memory anyway
            self.garbage_bytes += len(buf)
            buf.clear()
        return frames, errors

    @property
    def pending(self) -> int:
        """Bytes held back awaiting the rest of a frame (or of a header split across reads)."""
        return len(self._buf)

    def reset(self) -> None:
        """Drop buffered bytes (counters are kept)."""
        self._buf.clear()


@dataclass(frozen=True, slots=True)
class TactileFrame:
    """One tactile array reading.

    Attributes:
        values: (n_elements,) read-only unsigned integers, 0 = no contact.
    """

    values: NDArray[np.integer]

    def contact_count(self, threshold: int = 0) -> int:
        """Number of elements reading above ``threshold`` (``n_c`` in the paper's eq. 7)."""
        return int(np.count_nonzero(self.values > threshold))

    def total(self) -> int:
        """Sum of all element readings (numerator of the paper's eq. 7)."""
        return int(self.values.sum(dtype=np.int64))


class SerialTactileArray(StreamingSource[TactileFrame]):
    """Background serial reader for the tactile array.

    Args:
        port: Device path, pty name or pyserial URL (``loop://``...); or an already created
            pyserial port object, whose ownership passes to this source (closed on ``stop``).
        baudrate: Line speed.
        frame_format: Wire format (default: header AA 55, 64 x uint8, no length, no checksum).
        name: Source name (default ``"tactile@<port>"``).
        read_timeout: Serial read timeout, bounds the ``stop()`` latency.
        expected_rate_hz: Nominal frame rate (for the rate monitor's ``late`` counter).
        serial_kwargs: Extra keyword arguments for ``serial.serial_for_url``.
    """

    def __init__(
        self,
        port: str | serial.SerialBase,
        baudrate: int = 115200,
        frame_format: TactileFrameFormat | None = None,
        *,
        name: str | None = None,
        read_timeout: float = 0.02,
        expected_rate_hz: float | None = None,
        serial_kwargs: dict[str, Any] | None = None,
    ) -> None:
        self.port = port
        self.port_name = port if isinstance(port, str) else str(getattr(port, "port", None) or port)
        super().__init__(name or f"tactile@{self.port_name}", expected_rate_hz=expected_rate_hz)
        self.baudrate = baudrate
        self.frame_format = frame_format or TactileFrameFormat()
        self.read_timeout = read_timeout
        self.serial_kwargs = dict(serial_kwargs or {})
        self.parser = TactileFrameParser(self.frame_format)
        self._ser: serial.SerialBase | None = None

    @property
    def device(self) -> str:
        """Device description used in error messages."""
        return f"tactile array on serial port {self.port_name}"

    def _open(self) -> None:
        try:
            import serial
        except ImportError as exc:  # pragma: no cover - pyserial is a declared dependency
            raise DeviceOpenError(self.device, "pyserial is not installed (pip install pyserial)") from exc
        self.parser.reset()
        if isinstance(self.port, str):
            try:
                ser = serial.serial_for_url(
                    self.port, baudrate=self.baudrate, timeout=self.read_timeout, **self.serial_kwargs
                )
            except (serial.SerialException, OSError, ValueError) as exc:
                raise DeviceOpenError(self.device, f"cannot open: {exc}") from exc
        else:
            ser = self.port
            if not ser.is_open:
                try:
                    ser.open()
                except (serial.SerialException, OSError) as exc:
                    raise DeviceOpenError(self.device, f"cannot open: {exc}") from exc
            ser.timeout = self.read_timeout
        self._ser = ser

    def _read_once(self) -> None:
        ser = self._ser
        if ser is None:
            raise RuntimeError("port closed")
        waiting = ser.in_waiting
        data = ser.read(min(max(waiting, 1), 4096))  # blocks <= read_timeout for the first byte
        if not data:
            return
        now = time.monotonic()
        frames, errors = self.parser.feed(data)
        for exc in errors:
            self._record_malformed(exc)
        for values in frames:
            values.flags.writeable = False
            self._publish(TactileFrame(values), now)

    def _interrupt(self) -> None:
        ser = self._ser
        if ser is not None and hasattr(ser, "cancel_read"):
            with contextlib.suppress(Exception):
                ser.cancel_read()

    def _close(self) -> None:
        ser, self._ser = self._ser, None
        if ser is not None:
            ser.close()
