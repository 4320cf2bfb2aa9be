"""6-axis force/torque sensors streaming over UDP: OnRobot HEX (compute box) and ATI Net F/T RDT.

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

Scaling assumptions (configurable, check them against your device)
------------------------------------------------------------------
* OnRobot HEX-E/H via the compute box: 10000 counts/N and 100000 counts/Nm, the defaults of the
  OnRobot/OptoForce EtherDAQ drivers above. The sensor's own calibration sheet is authoritative.
* ATI Net F/T: 1000000 counts/N and 1000000 counts/Nm, the Net F/T default calibration with force
  in N and torque in N·m. The true values are the device's "Counts per Force/Torque" settings
  (``cfgcpf``/``cfgcpt`` in ``http://<box>/netftapi2.xml``); torque in N·mm gives 1e9 counts/Nm
  (the value ``ati_netft_ros_driver`` hard-codes).

Output
------
Inside this module the six values travel in the record's order, :data:`WIRE_ORDER`
``[Fx, Fy, Fz, Tx, Ty, Tz]`` (force first, unlike lapwrench's ``[moment; force]`` wrenches of
:mod:`lapwrench.spatial`). Nothing leaves the driver in that order: each accepted record is
published as a :class:`Wrench` with named parts (force (3,) N, torque (3,) N·m, sensor
frame, bias removed) in a :class:`~lapwrench.buffer.LatestValue`; the sample timestamp is
the host ``time.monotonic()`` at reception. Malformed datagrams (wrong length, a request header
where a record is expected, non-zero status) raise :class:`~lapwrench.drivers.base.PacketError`
inside the reader thread, where they are counted and reported without stopping the thread.
Polled mode: :meth:`UdpForceTorqueSensor.start_polled` opens a non-blocking socket and starts no
thread; its owner calls :meth:`UdpForceTorqueSensor.drain` (e.g. at the start of each control
cycle), which reads every pending datagram and publishes the newest valid one.
UDP has no retransmission: the start command is re-sent until data arrives (like the public
drivers), and lost records only show up as sequence gaps (``status().drops``).
"""

from __future__ import annotations

import contextlib
import socket
import struct
import threading
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lapwrench.drivers.base import DeviceOpenError, DeviceTimeoutError, PacketError, StreamingSource

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


def _named(w: NDArray[np.float64]) -> Wrench:
    """A (6,) array in :data:`WIRE_ORDER` as a :class:`Wrench` (views of ``w``)."""
    return Wrench(w[:3], w[3:])


def wire_counts(
    force: ArrayLike, torque: ArrayLike = (0.0, 0.0, 0.0), *, counts_per_force: float, counts_per_torque: float
) -> NDArray[np.float64]:
    """The six raw counts (rounded, :data:`WIRE_ORDER`) a device sends for ``force`` (N) and
    ``torque`` (N·m): what a simulated device streams (e.g. :class:`~lapwrench.drivers.fakes.FakeFTDevice`)."""
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


def unpack_record(data: bytes) -> FTRecord:
    """Decode one 36-byte record.

    Raises:
        PacketError: the datagram is not exactly 36 bytes, or it starts with the request header
            and is 8 bytes long (a command echoed back / sent to the wrong port).
    """
    n = len(data)
    if n != RECORD_SIZE:
        if n == REQUEST_SIZE and data[:2] == RDT_HEADER.to_bytes(2, "big"):
            raise PacketError("received a request packet (header 0x1234) where a record was expected")
        raise PacketError(f"record of {n} bytes, expected {RECORD_SIZE}")
    seq, ft_seq, status, *counts = _RECORD.unpack(data)
    return FTRecord(seq, ft_seq, status, tuple(counts))  # type: ignore[arg-type]


class _TareCollector:
    """Accumulates raw samples for a tare requested by another thread."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.samples: list[NDArray[np.float64]] = []
        self.done = threading.Event()


class UdpForceTorqueSensor(StreamingSource[Wrench]):
    """Background UDP reader for devices speaking the 0x1234 RDT/EtherDAQ protocol.

    Use :class:`OnRobotHexSensor` or :class:`AtiNetFTSensor`, which only change defaults.

    Args:
        host: Device address (IPv4 literal or name).
        port: Device UDP port (49152 on real hardware; tests use an ephemeral port).
        counts_per_force: Raw counts per newton.
        counts_per_torque: Raw counts per newton-metre.
        name: Source name for errors and logs (default ``"<kind>@host:port"``).
        expected_rate_hz: Nominal streaming rate (only used for the ``late`` counter).
        start_timeout: Seconds ``start()`` waits for the first valid record.
        start_retry_s: Re-send the start command this often until data arrives.
        recv_timeout: Poll timeout of the reader thread (bounds ``stop()`` latency).
        status_error_mask: Records with ``status & mask != 0`` are rejected as
            :class:`StatusError` (default: any non-zero status; the OnRobot ROS node likewise
            stops on a non-zero status).
        send_stop_on_close: Send the stop-streaming command when stopping.
        max_force, max_torque: A record beyond these (N, N m; far above the rated range of the
            supported sensors, e.g. 200 N for a HEX-E) is corrupt and rejected. The RDT record has
            no checksum, so corruption inside the range cannot be told from data; the controller's
            own range check (``interaction.force_range``) applies on top.
    """

    kind = "F/T"

    def __init__(
        self,
        host: str,
        port: int = DEFAULT_PORT,
        *,
        counts_per_force: float,
        counts_per_torque: float,
        name: str | None = None,
        expected_rate_hz: float | None = None,
        start_timeout: float = 1.0,
        start_retry_s: float = 0.1,
        recv_timeout: float = 0.05,
        status_error_mask: int = 0xFFFFFFFF,
        send_stop_on_close: bool = True,
        max_force: float = 2000.0,
        max_torque: float = 100.0,
    ) -> None:
        if counts_per_force <= 0 or counts_per_torque <= 0:
            raise ValueError("counts_per_force and counts_per_torque must be > 0")
        self.host = host
        self.port = int(port)
        super().__init__(name or f"{self.kind}@{host}:{port}", expected_rate_hz=expected_rate_hz)
        self.counts_per_force = float(counts_per_force)
        self.counts_per_torque = float(counts_per_torque)
        self.start_timeout = start_timeout
        self.start_retry_s = start_retry_s
        self.recv_timeout = recv_timeout
        self.status_error_mask = status_error_mask
        self.send_stop_on_close = send_stop_on_close
        self.max_force = float(max_force)
        self.max_torque = float(max_torque)
        self._sock: socket.socket | None = None
        self._scale = np.array([1.0 / self.counts_per_force] * 3 + [1.0 / self.counts_per_torque] * 3)
        self._bias = np.zeros(6)
        self._tare: _TareCollector | None = None
        self._polled = False
        self.last_status = 0
        """Most recent non-zero device status word (0 if none was seen)."""

    @property
    def device(self) -> str:
        """Device description used in error messages."""
        return f"{self.kind} sensor at udp://{self.host}:{self.port}"

    # ----------------------------------------------------------------- device I/O
    def _open(self) -> None:
        try:
            sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        except OSError as exc:  # pragma: no cover - resource exhaustion
            raise DeviceOpenError(self.device, f"cannot create UDP socket: {exc}") from exc
        try:
            # connect() fixes the peer: datagrams from other hosts are dropped by the kernel.
            sock.connect((self.host, self.port))
        except OSError as exc:
            sock.close()
            raise DeviceOpenError(self.device, f"cannot reach device: {exc}") from exc
        sock.settimeout(self.recv_timeout)
        self._sock = sock

    def _close(self) -> None:
        self._polled = False
        sock, self._sock = self._sock, None
        if sock is None:
            return
        if self.send_stop_on_close:
            with contextlib.suppress(OSError):
                sock.send(pack_request(CMD_STOP, 0))
        sock.close()

    def _interrupt(self) -> None:
        # The socket has a short timeout; the reader notices the stop event within recv_timeout.
        pass

    def send_command(self, command: int, data: int = 0) -> None:
        """Send one raw 8-byte request (header 0x1234) to the device."""
        sock = self._sock
        if sock is None:
            raise RuntimeError(f"{self.name}: not started")
        sock.send(pack_request(command, data))

    def _configure_device(self) -> None:
        """Hook for device-specific configuration sent before the start command."""

    def _after_thread_start(self) -> None:
        try:
            self._configure_device()
        except OSError as exc:
            raise DeviceOpenError(self.device, f"configuration command failed: {exc}") from exc
        self.rate.forget_seq()  # the device restarts its sequence counter on a new start command
        latest = self.buffer.get()
        seq0 = 0 if latest is None else latest.seq  # wait for data newer than a previous run's
        deadline = time.monotonic() + self.start_timeout
        last_err: str | None = None
        while True:
            try:
                self.send_command(CMD_START_REALTIME, 0)
            except OSError as exc:  # e.g. ECONNREFUSED from an earlier ICMP unreachable
                last_err = str(exc)
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            if self.buffer.wait_newer(seq0, min(self.start_retry_s, remaining)) is not None:
                return
            if time.monotonic() >= deadline:
                break
        st = self.status()
        detail = f"; last error: {st.last_error or last_err}" if (st.last_error or last_err) else ""
        raise DeviceTimeoutError(
            self.device,
            f"no valid record within {self.start_timeout:.2f} s "
            f"(malformed={st.malformed}, io_errors={st.io_errors}{detail})",
        )

    def _read_once(self) -> None:
        sock = self._sock
        if sock is None:
            raise RuntimeError("socket closed")
        try:
            data = sock.recv(2048)
        except TimeoutError:
            return
        now = time.monotonic()
        self._handle_datagram(data, now)

    def _handle_datagram(self, data: bytes, now: float) -> None:
        accepted = self._accept_datagram(data)
        if accepted is not None:
            self._publish_raw(*accepted, now)

    def _accept_datagram(self, data: bytes) -> tuple[NDArray[np.float64], FTRecord] | None:
        """Decode and check one datagram (sequence, status, tare); the raw wrench (N, N·m, bias
        not removed, :data:`WIRE_ORDER`) and its record, or ``None`` for a duplicate/out-of-order record.

        Raises:
            PacketError: malformed datagram or (:class:`StatusError`) a device status error.
        """
        rec = unpack_record(data)
        # the checks of the record itself come first: a rejected record never moves the sequence
        if rec.status & self.status_error_mask:
            self.last_status = rec.status
            raise StatusError(f"device status 0x{rec.status:08x}")
        raw = np.asarray(rec.counts, dtype=np.float64) * self._scale
        f, m = float(np.linalg.norm(raw[:3])), float(np.linalg.norm(raw[3:]))
        if not (f <= self.max_force and m <= self.max_torque):
            raise PacketError(f"wrench beyond any sensor's range (|F| {f:.0f} N, |M| {m:.1f} N m): corrupt record")
        if not self.rate.check_seq(rec.sequence):
            return None  # duplicate / out-of-order / an unconfirmed far jump, counted by the rate monitor
        tare = self._tare
        if tare is not None and not tare.done.is_set():
            tare.samples.append(raw)
            if len(tare.samples) >= tare.n:
                tare.done.set()
        return raw, rec

    def _publish_raw(self, raw: NDArray[np.float64], rec: FTRecord, now: float) -> None:
        w = raw - self._bias
        w.flags.writeable = False
        self._publish(Wrench(w[:3], w[3:], rec.ft_sequence, rec.status), now)

    # ----------------------------------------------------------------- polled mode (no thread)
    @property
    def polled(self) -> bool:
        """True while the source runs without a reader thread (:meth:`start_polled`)."""
        return self._polled and self._sock is not None

    def start_polled(self) -> UdpForceTorqueSensor:
        """Open the socket *non-blocking* and start streaming without a reader thread.

        The owner then calls :meth:`drain` (e.g. at the start of every control cycle): nothing
        else reads the socket, so no thread of this process competes with the caller for the
        interpreter. Waits (here, not in :meth:`drain`) up to ``start_timeout`` for a first valid
        record, re-sending the start command, like :meth:`start`.

        Raises:
            DeviceOpenError: the device cannot be opened or configured.
            DeviceTimeoutError: no valid record arrived in time (the source is stopped).
            RuntimeError: the source is already running.
        """
        if self.running or self.polled:
            raise RuntimeError(f"{self.name}: already started")
        self._stop_event.clear()
        self._open()
        self._opened = True
        self._polled = True
        assert self._sock is not None
        self._sock.setblocking(False)
        try:
            try:
                self._configure_device()
            except OSError as exc:
                raise DeviceOpenError(self.device, f"configuration command failed: {exc}") from exc
            self.rate.forget_seq()
            latest = self.buffer.get()
            seq0 = 0 if latest is None else latest.seq
            deadline = time.monotonic() + self.start_timeout
            last_err: str | None = None
            next_send = 0.0
            while True:
                now = time.monotonic()
                if now >= next_send:
                    try:
                        self.send_command(CMD_START_REALTIME, 0)
                    except OSError as exc:
                        last_err = str(exc)
                    next_send = now + self.start_retry_s
                self.drain()
                s = self.buffer.get()
                if s is not None and s.seq > seq0:
                    return self
                if time.monotonic() >= deadline:
                    break
                time.sleep(0.001)
            st = self.status()
            detail = f"; last error: {st.last_error or last_err}" if (st.last_error or last_err) else ""
            raise DeviceTimeoutError(
                self.device,
                f"no valid record within {self.start_timeout:.2f} s "
                f"(malformed={st.malformed}, io_errors={st.io_errors}{detail})",
            )
        except BaseException:
            self.stop()
            raise

    def drain(self, now: float | None = None, max_datagrams: int = 1024) -> int:
        """Read every pending datagram without blocking; publish the newest valid one.

        Every datagram goes through the same checks as in the thread mode (sequence accounting,
        status word, tare collection; malformed ones are counted); only the newest valid record
        is published, stamped ``now`` (default ``time.monotonic()``): the time it was taken off
        the socket, at most one drain period after it arrived. Returns the number of datagrams
        read. Never raises on I/O: an error (e.g. ICMP port unreachable) is counted and the data
        goes stale.
        """
        sock = self._sock
        if sock is None:
            return 0
        newest: tuple[NDArray[np.float64], FTRecord] | None = None
        n = 0
        while n < max_datagrams:
            try:
                data = sock.recv(2048)
            except (BlockingIOError, InterruptedError):
                break
            except OSError as exc:
                self._record_io_error(exc)
                break
            n += 1
            try:
                accepted = self._accept_datagram(data)
            except PacketError as exc:
                self._record_malformed(exc)
                continue
            if accepted is not None:
                newest = accepted
        if newest is not None:
            self._publish_raw(*newest, time.monotonic() if now is None else now)
        return n

    poll = drain

    # ----------------------------------------------------------------- bias / tare
    @property
    def bias(self) -> Wrench:
        """Current software bias (force N, torque N·m; copies), subtracted from every sample."""
        return _named(self._bias.copy())

    def set_bias(self, *, force: ArrayLike, torque: ArrayLike) -> None:
        """Set the software bias: ``force`` (3,) N and ``torque`` (3,) N·m, sensor frame."""
        f, m = np.asarray(force, dtype=np.float64).reshape(3), np.asarray(torque, dtype=np.float64).reshape(3)
        self._set_bias(np.concatenate((f, m)))  # WIRE_ORDER

    def _set_bias(self, bias: NDArray[np.float64]) -> None:
        """Set the software bias from a (6,) array in :data:`WIRE_ORDER`."""
        if not np.all(np.isfinite(bias)):
            raise ValueError("bias must be finite")
        self._bias = bias  # atomic reference swap, read by the reader thread

    def clear_bias(self) -> None:
        """Remove the software bias."""
        self._set_bias(np.zeros(6))

    def tare(self, n_samples: int = 100, timeout: float = 2.0) -> Wrench:
        """Average the next ``n_samples`` raw records and use the mean as the software bias.

        Blocks the caller (never the reader thread) for up to ``timeout`` s; in polled mode
        (:meth:`start_polled`) it drains the socket itself meanwhile. Call it while the handle is
        not touched. Returns the new bias (:attr:`bias`).

        Raises:
            RuntimeError: the source is not running.
            DeviceTimeoutError: fewer than ``n_samples`` records arrived within ``timeout``.
        """
        if n_samples < 1:
            raise ValueError("n_samples must be >= 1")
        if not (self.running or self.polled):
            raise RuntimeError(f"{self.name}: tare needs a running source")
        collector = _TareCollector(n_samples)
        self._tare = collector
        try:
            if self.polled:  # no reader thread: drain here until enough samples came in
                deadline = time.monotonic() + timeout
                while not collector.done.is_set() and time.monotonic() < deadline:
                    self.drain()
                    time.sleep(0.0005)
            if not collector.done.wait(0.0 if self.polled else timeout):
                raise DeviceTimeoutError(
                    self.device,
                    f"tare got {len(collector.samples)}/{n_samples} samples in {timeout:.2f} s",
                )
        finally:
            self._tare = None
        bias = np.mean(np.stack(collector.samples[:n_samples]), axis=0)
        self._set_bias(bias)
        return _named(bias.copy())


class OnRobotHexSensor(UdpForceTorqueSensor):
    """OnRobot HEX-E/HEX-H (as in the paper's handle) through its compute box, EtherDAQ UDP mode.

    Args:
        host: Compute box address (OnRobot default 192.168.1.1).
        port: UDP port (49152 on the device).
        counts_per_force: Default 10000 counts/N (OnRobot/OptoForce EtherDAQ driver default).
        counts_per_torque: Default 100000 counts/Nm (same source).
        rate_hz: If given, send the speed command (word = round(1000 / rate_hz)) before starting.
        filter_code: If given, send the filter command: 0 none, 1 500 Hz, 2 150 Hz, 3 50 Hz,
            4 15 Hz, 5 5 Hz, 6 1.5 Hz.
        hardware_bias: If not None, send the device bias command before starting (True: 0xFF
            bias on, False: 0x00 bias off). The software :meth:`tare` works either way.
        **kwargs: Forwarded to :class:`UdpForceTorqueSensor`.
    """

    kind = "OnRobot HEX"

    def __init__(
        self,
        host: str,
        port: int = DEFAULT_PORT,
        *,
        counts_per_force: float = 10000.0,
        counts_per_torque: float = 100000.0,
        rate_hz: float | None = None,
        filter_code: int | None = None,
        hardware_bias: bool | None = None,
        **kwargs: Any,
    ) -> None:
        if rate_hz is not None and not 1.0 <= rate_hz <= 1000.0:
            raise ValueError("rate_hz must be within [1, 1000]")
        if filter_code is not None and filter_code not in range(7):
            raise ValueError("filter_code must be 0..6")
        kwargs.setdefault("expected_rate_hz", rate_hz)
        super().__init__(
            host,
            port,
            counts_per_force=counts_per_force,
            counts_per_torque=counts_per_torque,
            **kwargs,
        )
        self.rate_hz = rate_hz
        self.filter_code = filter_code
        self.hardware_bias = hardware_bias

    def _configure_device(self) -> None:
        if self.rate_hz is not None:
            self.send_command(CMD_SET_SPEED, round(1000.0 / self.rate_hz))
        if self.filter_code is not None:
            self.send_command(CMD_SET_FILTER, self.filter_code)
        if self.hardware_bias is not None:
            self.set_hardware_bias(self.hardware_bias)

    def set_hardware_bias(self, enable: bool = True) -> None:
        """Toggle the compute box's own bias (command 0x0042, data 0xFF on / 0x00 off)."""
        self.send_command(CMD_BIAS, 0xFF if enable else 0x00)


class AtiNetFTSensor(UdpForceTorqueSensor):
    """ATI Net F/T (NETBA/NETCANOEM, also Axia80 RDT) real-time RDT streaming.

    Args:
        host: Net F/T box address (ATI default 192.168.1.1).
        port: UDP port (49152 on the device).
        counts_per_force: Default 1000000 counts/N (Net F/T default calibration, force in N).
        counts_per_torque: Default 1000000 counts/Nm (torque in N·m). Read ``cfgcpf``/``cfgcpt``
            from ``netftapi2.xml`` on the box for the real values.
        **kwargs: Forwarded to :class:`UdpForceTorqueSensor`.
    """

    kind = "ATI Net F/T"

    def __init__(
        self,
        host: str,
        port: int = DEFAULT_PORT,
        *,
        counts_per_force: float = 1_000_000.0,
        counts_per_torque: float = 1_000_000.0,
        **kwargs: Any,
    ) -> None:
        super().__init__(
            host,
            port,
            counts_per_force=counts_per_force,
            counts_per_torque=counts_per_torque,
            **kwargs,
        )

    def set_hardware_bias(self) -> None:
        """Ask the Net F/T to bias itself (RDT command 0x0042, 'set software bias')."""
        self.send_command(CMD_BIAS, 0)
