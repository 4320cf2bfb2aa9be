"""The UDP reader of the RDT/EtherDAQ F/T sensors: socket, reader thread, record checks, bias.

Each accepted record is published as a :class:`~lapwrench.drivers.ft.wire.Wrench` with named parts
(force (3,) N, torque (3,) N·m, sensor frame, bias removed) in a
:class:`~lapwrench.buffer.LatestValue`; the sample timestamp is the host ``time.monotonic()`` at
the datagram's arrival (the kernel's receive stamp, :mod:`lapwrench.drivers.arrival`: a datagram read
late is stamped as old as it is). Malformed datagrams (wrong length, a request header where a record
is expected, non-zero status, a wrench beyond any sensor's range) raise :class:`~lapwrench.drivers.base.PacketError`
inside the reader thread, where they are counted and reported without stopping the thread.
Sequence numbers go through the source's :class:`~lapwrench.buffer.RateMonitor`.
UDP has no retransmission: the start command is re-sent until data arrives (like the public
drivers), and lost records only show up as sequence gaps (``status().drops``).
"""

from __future__ import annotations

import contextlib
import math
import select
import socket
import struct
import threading
import time

import numpy as np
from numpy.typing import ArrayLike, NDArray

from lapwrench.drivers import arrival
from lapwrench.drivers.base import DeviceOpenError, DeviceTimeoutError, PacketError, StreamingSource
from lapwrench.drivers.ft.wire import (
    CMD_START_REALTIME,
    CMD_STOP,
    DEFAULT_PORT,
    StatusError,
    Wrench,
    named_wrench,
    pack_request,
    record_fields,
)

__all__ = ["TareCollector", "UdpRecordStream"]

_THREE = struct.Struct("3d")  # native float64: what numpy reads back from the packed bytes
_from_bytes = np.frombuffer


class TareCollector:
    """Accumulates raw samples for a tare requested by another thread."""

    def __init__(self, n: int) -> None:
        self.n = n
        self.samples: list[NDArray[np.float64]] = []
        self.done = threading.Event()


class UdpRecordStream(StreamingSource[Wrench]):
    """Background UDP reader for devices speaking the 0x1234 RDT/EtherDAQ protocol.

    The reader-thread half of :class:`~lapwrench.drivers.ft.sensor.UdpForceTorqueSensor`; use
    :class:`~lapwrench.drivers.ft.OnRobotHexSensor` or :class:`~lapwrench.drivers.ft.AtiNetFTSensor`.

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
        self._pending = select.poll()  # the socket's readiness (registered when it opens)
        self._per_count = (1.0 / self.counts_per_force, 1.0 / self.counts_per_torque)  # N, N m per count
        self._bias = [0.0] * 6  # N, N m (WIRE_ORDER), as floats: subtracted from every record's six floats
        self._tare: TareCollector | None = None
        self._polled = False
        self._kernel_stamps = False  # the socket's datagrams carry the kernel's arrival stamp
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
        self._kernel_stamps = arrival.enable(sock)
        self._pending = select.poll()  # the polled drain asks it before each read (sensor.py)
        self._pending.register(sock, select.POLLIN)
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

    def _begin_streaming(self) -> tuple[int, float]:
        """Configure the device for a new start; returns (the newest sequence before it, the deadline
        for a first valid record). Both start paths (threaded and polled) begin here."""
        try:
            self._configure_device()
        except OSError as exc:
            raise DeviceOpenError(self.device, f"configuration command failed: {exc}") from exc
        self.rate.forget_seq()  # the device restarts its sequence counter on a new start command
        latest = self.buffer.get()
        seq0 = 0 if latest is None else latest.seq  # wait for data newer than a previous run's
        return seq0, time.monotonic() + self.start_timeout

    def _no_record_error(self, last_err: str | None) -> DeviceTimeoutError:
        """The start-up timeout, with the counts and the last error (the device's or a send's)."""
        st = self.status()
        detail = f"; last error: {st.last_error or last_err}" if (st.last_error or last_err) else ""
        return DeviceTimeoutError(
            self.device,
            f"no valid record within {self.start_timeout:.2f} s "
            f"(malformed={st.malformed}, io_errors={st.io_errors}{detail})",
        )

    def _after_thread_start(self) -> None:
        seq0, deadline = self._begin_streaming()
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
        raise self._no_record_error(last_err)

    def _read_once(self) -> None:
        sock = self._sock
        if sock is None:
            raise RuntimeError("socket closed")
        try:
            data, stamp = self._recv(sock)
        except TimeoutError:
            return
        self._handle_datagram(data, arrival.on_clock(stamp, time.monotonic(), time.time()))

    def _recv(self, sock: socket.socket) -> tuple[bytes, float | None]:
        """One datagram and its kernel arrival stamp (wall clock; None without one)."""
        if self._kernel_stamps:
            return arrival.recv_stamped(sock, 2048)
        return sock.recv(2048), None

    def _handle_datagram(self, data: bytes, now: float) -> None:
        accepted = self._accept_datagram(data)
        if accepted is not None:
            self._publish_raw(*accepted, now)

    def feed(self, data: bytes, now: float) -> bool:
        """Handle one datagram received at ``now`` exactly as the reader thread does, without a
        socket (to replay a captured stream): publish it if it passes the checks, count it if it
        is malformed. True if it was published.
        """
        try:
            accepted = self._accept_datagram(data)
        except PacketError as exc:
            self._record_malformed(exc)
            return False
        if accepted is None:
            return False
        self._publish_raw(*accepted, now)
        return True

    def _accept_datagram(self, data: bytes) -> tuple[list[float], int, int] | None:
        """Decode and check one datagram (sequence, status, tare); the raw wrench (N, N·m, bias
        not removed, :data:`WIRE_ORDER`), the device's sample counter and status word, or ``None`` for a
        duplicate/out-of-order record.

        The six numbers stay Python floats until :meth:`_publish_raw` makes the newest one an array, and
        the record's fields stay the decoded tuple (no record object): the polled loop decodes a record
        every cycle, and numpy's or a dataclass's per-call overhead dwarfs six products.

        Raises:
            PacketError: malformed datagram or (:class:`StatusError`) a device status error.
        """
        seq, ft_seq, status, c0, c1, c2, c3, c4, c5 = record_fields(data)
        # the checks of the record itself come first: a rejected record never moves the sequence
        if status & self.status_error_mask:
            self.last_status = status
            raise StatusError(f"device status 0x{status:08x}")
        kf, kt = self._per_count
        v = [c0 * kf, c1 * kf, c2 * kf, c3 * kt, c4 * kt, c5 * kt]
        f, m = math.hypot(v[0], v[1], v[2]), math.hypot(v[3], v[4], v[5])
        if not (f <= self.max_force and m <= self.max_torque):
            raise PacketError(f"wrench beyond any sensor's range (|F| {f:.0f} N, |M| {m:.1f} N m): corrupt record")
        if not self.rate.check_seq(seq):
            return None  # duplicate / out-of-order / an unconfirmed far jump, counted by the rate monitor
        tare = self._tare
        if tare is not None and not tare.done.is_set():
            tare.samples.append(np.array(v))
            if len(tare.samples) >= tare.n:
                tare.done.set()
        return v, ft_seq, status

    def _publish_raw(self, raw: list[float], ft_sequence: int, status: int, now: float) -> None:
        """The record as a :class:`Wrench`, bias removed, into the buffer. Each part is an array over the bytes
        its three doubles were packed into: read-only as it is made (an array's ``flags.writeable = False``
        and its two slices cost the 1 kHz drain as much again, measured)."""
        b = self._bias
        force = _from_bytes(_THREE.pack(raw[0] - b[0], raw[1] - b[1], raw[2] - b[2]))
        torque = _from_bytes(_THREE.pack(raw[3] - b[3], raw[4] - b[4], raw[5] - b[5]))
        self._publish(Wrench(force, torque, ft_sequence, status), now)


    # ----------------------------------------------------------------- polled mode (no thread)
    @property
    def polled(self) -> bool:
        """True while the source runs without a reader thread (:meth:`start_polled`)."""
        return self._polled and self._sock is not None

    # ----------------------------------------------------------------- bias / tare
    @property
    def bias(self) -> Wrench:
        """Current software bias (force N, torque N·m; copies), subtracted from every sample."""
        return named_wrench(np.array(self._bias))

    def set_bias(self, *, force: ArrayLike, torque: ArrayLike) -> None:
        """Set the software bias: ``force`` (3,) N and ``torque`` (3,) N·m, sensor frame."""
        f, m = np.asarray(force, dtype=np.float64).reshape(3), np.asarray(torque, dtype=np.float64).reshape(3)
        self._set_bias(np.concatenate((f, m)))  # WIRE_ORDER

    def _set_bias(self, bias: NDArray[np.float64]) -> None:
        """Set the software bias from a (6,) array in :data:`WIRE_ORDER`."""
        if not np.all(np.isfinite(bias)):
            raise ValueError("bias must be finite")
        self._bias = bias.tolist()  # atomic reference swap, read by the reader thread

    def clear_bias(self) -> None:
        """Remove the software bias."""
        self._set_bias(np.zeros(6))
