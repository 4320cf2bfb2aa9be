"""A simulated OnRobot HEX compute box on loopback UDP (``run --dry-run``, tests, benchmarks).

:class:`SimulatedHexBox` is a UDP peer that behaves like an OnRobot HEX compute box or an ATI Net
F/T box: it answers the 0x1234 start command by streaming 36-byte records to the requesting
address at a fixed rate, honours stop/bias commands, and can inject malformed datagrams, sequence
gaps, duplicates, non-zero status words and pauses (to make the host-side data go stale).

Everything binds to 127.0.0.1 by default; the port is ephemeral unless given.
"""

from __future__ import annotations

import contextlib
import os
import select
import socket
import threading
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import Self

import numpy as np
from numpy.typing import ArrayLike

from lapwrench.drivers.base import PacketError
from lapwrench.drivers.ft import (
    CMD_BIAS,
    CMD_START_REALTIME,
    CMD_STOP,
    pack_record,
    unpack_request,
)

__all__ = ["SimulatedHexBox"]

CountsFn = Callable[[int], ArrayLike]


class SimulatedHexBox:
    """A UDP F/T box on loopback speaking the RDT/EtherDAQ protocol.

    Args:
        rate_hz: Record rate while streaming.
        counts: Constant raw counts ``[Fx, Fy, Fz, Tx, Ty, Tz]`` to stream (ignored if
            ``counts_fn`` is given). Can be changed at run time via :attr:`counts`.
        counts_fn: ``f(i) -> counts`` for record ``i`` (0-based since start).
        host: Address to bind (keep the default loopback).
        port: Port to bind (0 = ephemeral; read :attr:`port` afterwards).
        device_bias: Emulate the device-side bias command (0x0042) by subtracting the current
            counts from later records.
        fifo_priority: SCHED_FIFO priority of the device thread, when permitted (silently not
            otherwise). A real box has a CPU of its own: with it, a busy machine does not delay its
            records, so a test or benchmark beside CPU-heavy work measures the host, not the box.

    Attributes:
        commands: Every well-formed request received, as ``(command, data)``.
        bad_requests: Requests with a wrong length or header (ignored, as the device would).
        sent: Number of records sent.
    """

    def __init__(
        self,
        rate_hz: float = 500.0,
        counts: ArrayLike = (0, 0, 0, 0, 0, 0),
        counts_fn: CountsFn | None = None,
        host: str = "127.0.0.1",
        port: int = 0,
        device_bias: bool = True,
        fifo_priority: int | None = None,
    ) -> None:
        self.period = 1.0 / rate_hz
        self.fifo_priority = fifo_priority
        self.counts = np.asarray(counts, dtype=np.int64).reshape(6)
        self.counts_fn = counts_fn
        self.status = 0
        self.device_bias = device_bias
        self.commands: list[tuple[int, int]] = []
        self.bad_requests = 0
        self.sent = 0
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind((host, port))
        self._sock.setblocking(False)
        self.host, self.port = self._sock.getsockname()[:2]
        self._client: tuple[str, int] | None = None
        self._streaming = False
        self._paused = threading.Event()
        self._stop = threading.Event()
        self._inject: deque[bytes] = deque()
        self._seq = 0
        self._index = 0
        self._skip = 0
        self._dup = 0
        self._bias = np.zeros(6, dtype=np.int64)
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._run, name="simulated-hex-box", daemon=True)

    # ----------------------------------------------------------------- control
    def start(self) -> Self:
        """Start the device thread."""
        self._thread.start()
        return self

    def close(self, timeout: float = 2.0) -> None:
        """Stop the device thread and close its socket."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout)
        self._sock.close()

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.close()

    @property
    def address(self) -> tuple[str, int]:
        """``(host, port)`` the device listens on."""
        return self.host, self.port

    @property
    def streaming(self) -> bool:
        """A client requested streaming and did not stop it."""
        return self._streaming

    def pause(self) -> None:
        """Stop sending records (silently, as if the cable were pulled)."""
        self._paused.set()

    def resume(self) -> None:
        """Resume sending records after :meth:`pause`."""
        self._paused.clear()

    def inject(self, datagrams: Iterable[bytes]) -> None:
        """Send these raw datagrams to the client before the next record."""
        with self._lock:
            self._inject.extend(datagrams)

    def skip(self, n: int) -> None:
        """Advance the sequence number by ``n`` extra counts (simulates ``n`` lost records)."""
        with self._lock:
            self._skip += n

    def duplicate(self, n: int = 1) -> None:
        """Re-send the previous sequence number ``n`` times (out-of-order records)."""
        with self._lock:
            self._dup += n

    # ----------------------------------------------------------------- thread
    def _handle_request(self, data: bytes, addr: tuple[str, int]) -> None:
        try:
            _, command, value = unpack_request(data)
        except PacketError:
            self.bad_requests += 1
            return
        self.commands.append((command, value))
        if command == CMD_START_REALTIME:
            self._client = addr
            if not self._streaming:
                self._seq = 0
                self._index = 0
            self._streaming = True
        elif command == CMD_STOP:
            self._streaming = False
        elif command == CMD_BIAS and self.device_bias:
            self._bias = self._current_counts().copy() if value != 0 else np.zeros(6, dtype=np.int64)

    def _current_counts(self) -> np.ndarray:
        if self.counts_fn is not None:
            return np.asarray(self.counts_fn(self._index), dtype=np.int64).reshape(6)
        return self.counts

    def _send_one(self) -> None:
        assert self._client is not None
        with self._lock:
            injected = list(self._inject)
            self._inject.clear()
            if self._dup > 0:
                self._dup -= 1
                seq = self._seq
            else:
                self._seq += 1 + self._skip
                self._skip = 0
                seq = self._seq
        for raw in injected:
            with contextlib.suppress(OSError):
                self._sock.sendto(raw, self._client)
        counts = self._current_counts() - self._bias
        rec = pack_record(seq, self._index, self.status, counts)
        self._index += 1
        with contextlib.suppress(OSError):
            self._sock.sendto(rec, self._client)
            self.sent += 1

    def _run(self) -> None:
        if self.fifo_priority:  # Linux: pid 0 is the calling thread, this device thread only
            with contextlib.suppress(OSError, AttributeError):
                os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(self.fifo_priority))
        next_t = time.monotonic()
        while not self._stop.is_set():
            timeout = max(0.0, next_t - time.monotonic()) if self._streaming else 0.02
            try:
                readable, _, _ = select.select([self._sock], [], [], timeout)
            except (OSError, ValueError):
                break
            if readable:
                try:
                    data, addr = self._sock.recvfrom(2048)
                except OSError:
                    continue
                self._handle_request(data, addr)
                continue
            if not self._streaming:
                next_t = time.monotonic()
                continue
            now = time.monotonic()
            if now < next_t:
                continue
            next_t = max(next_t + self.period, now)
            if not self._paused.is_set():
                self._send_one()
