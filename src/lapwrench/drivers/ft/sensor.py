"""The UDP F/T sensor base: the reader of :mod:`~lapwrench.drivers.ft.stream` plus polled mode and tare.

Polled mode: :meth:`UdpForceTorqueSensor.start_polled` opens a non-blocking socket and starts no
thread; its owner calls :meth:`UdpForceTorqueSensor.drain` (e.g. at the start of each control
cycle), which reads every pending datagram and publishes the newest valid one.
:meth:`UdpForceTorqueSensor.tare` averages raw records into the software bias, in either mode.
"""

from __future__ import annotations

import time

import numpy as np

from lapwrench.drivers import arrival
from lapwrench.drivers.base import DeviceTimeoutError, PacketError
from lapwrench.drivers.ft.stream import TareCollector, UdpRecordStream
from lapwrench.drivers.ft.wire import CMD_START_REALTIME, Wrench, named_wrench

__all__ = ["UdpForceTorqueSensor"]


class UdpForceTorqueSensor(UdpRecordStream):
    """Background UDP reader for devices speaking the 0x1234 RDT/EtherDAQ protocol.

    Use :class:`~lapwrench.drivers.ft.OnRobotHexSensor` or :class:`~lapwrench.drivers.ft.AtiNetFTSensor`,
    which only change defaults. Arguments: see :class:`~lapwrench.drivers.ft.stream.UdpRecordStream`.
    Runs with a reader thread (:meth:`start`) or without one (:meth:`start_polled` + :meth:`drain`).
    """

    # ----------------------------------------------------------------- polled mode (no thread)
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
            seq0, deadline = self._begin_streaming()
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
            raise self._no_record_error(last_err)
        except BaseException:
            self.stop()
            raise

    def drain(self, now: float | None = None, max_datagrams: int = 1024) -> int:
        """Read the pending datagrams without blocking, at most ``max_datagrams``; publish the newest valid one.

        Every datagram goes through the same checks as in the thread mode (sequence accounting,
        status word, tare collection; malformed ones are counted); only the newest valid record
        is published, stamped with its arrival time (the kernel's receive stamp,
        :mod:`lapwrench.drivers.arrival`) on the clock of ``now`` (default ``time.monotonic()``; ``now``
        must be that clock's current time): a backlog read after a stall is as old as it is. Without a
        kernel stamp, the time it was taken off the socket. What ``max_datagrams`` leaves stays queued for
        the next drain (a flood of datagrams cannot hold the caller). Returns the number of datagrams
        read. Never raises on I/O: an error (e.g. ICMP port unreachable) is counted and the data
        goes stale.
        """
        sock = self._sock
        if sock is None:
            return 0
        newest: tuple[list[float], int, int] | None = None
        stamp: float | None = None
        n = 0
        # a read after the first is preceded by a poll of the socket (about 1 us) rather than ended by the read
        # that raises BlockingIOError (an exception built and caught: about 3 us, every cycle, cold 6); a pending
        # error (ICMP port unreachable) polls as ready, and its read raises it
        pending = self._pending.poll
        while n < max_datagrams and (n == 0 or pending(0)):
            try:
                data, arrived = self._recv(sock)
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
                newest, stamp = accepted, arrived
        if newest is not None:
            t = time.monotonic() if now is None else now
            self._publish_raw(*newest, arrival.on_clock(stamp, t, time.time()))
        return n

    poll = drain

    # ----------------------------------------------------------------- tare
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
        collector = TareCollector(n_samples)
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
        return named_wrench(bias.copy())
