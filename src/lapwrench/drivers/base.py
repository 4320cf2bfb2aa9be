"""Common machinery for background-thread sensor sources.

A :class:`StreamingSource` owns one device connection and one reader thread. Its life cycle:

1. ``start()`` calls :meth:`StreamingSource._open` *in the caller's thread*, so a missing or
   unreachable device raises :class:`DeviceOpenError` (naming the device) before any thread runs
   and before the robot is allowed to move.
2. The reader thread calls :meth:`StreamingSource._read_once` in a loop. Each call blocks for at
   most a short poll timeout, so ``stop()`` is honoured promptly.
   * :class:`PacketError` (malformed input) is counted and reported; the thread keeps running.
   * Any other exception (I/O failure, device gone) is counted as an I/O error, reported, and
     retried after a short back-off; the thread keeps running and the data simply goes stale.
   * :class:`EndOfStream` (e.g. the end of a video file) ends the thread cleanly.

   Warnings are logged (rate-limited) only once the device has streamed a first value: before
   that, the start-up check that waits for one (e.g. the F/T box's first record) fails with one
   error that carries the counts and the last error, so a device that never answers gives one
   line, not a warning per retry.
3. ``stop()`` sets the stop event, lets the subclass interrupt blocking calls, joins the thread
   with a timeout and releases the device. It is idempotent; sources are also context managers.

Consumers never talk to the thread: they read :attr:`StreamingSource.buffer` (a
:class:`~lapwrench.buffer.LatestValue`) and decide freshness from the sample timestamp.
"""

from __future__ import annotations

import logging
import threading
import time
from abc import ABC, abstractmethod
from collections import deque
from dataclasses import dataclass
from typing import Generic, Self, TypeVar

from lapwrench.buffer import LatestValue, RateMonitor, Sample

__all__ = [
    "DeviceError",
    "DeviceOpenError",
    "DeviceTimeoutError",
    "EndOfStream",
    "PacketError",
    "SourceStatus",
    "StreamingSource",
]

T = TypeVar("T")

log = logging.getLogger(__name__)


class PacketError(ValueError):
    """A malformed packet, frame or image (wrong length, header, checksum, shape...).

    Raised by the parsers; inside a reader thread it is counted in ``status().malformed`` and the
    thread continues with the next packet.
    """


class DeviceError(RuntimeError):
    """A device-level failure. ``device`` names the device (address, port, path or index)."""

    def __init__(self, device: str, message: str) -> None:
        super().__init__(f"{device}: {message}")
        self.device = device


class DeviceOpenError(DeviceError):
    """The device could not be opened (absent, unreachable, busy or wrong format)."""


class DeviceTimeoutError(DeviceError):
    """The device was opened but sent no valid data within the start-up timeout."""


class EndOfStream(Exception):  # noqa: N818 - a control-flow signal, not an error
    """Raised by ``_read_once`` when the source is exhausted (e.g. end of a video file)."""


@dataclass(frozen=True, slots=True)
class SourceStatus:
    """Health snapshot of a source, for supervisors, logs and diagnostics.

    Attributes:
        name: Source name.
        running: The reader thread is alive.
        finished: The source ended (end of file) rather than being stopped.
        samples: Samples published so far.
        rate_hz: Sliding-window publish rate.
        age_s: Age of the latest sample (``inf`` if none).
        malformed: Malformed packets/frames rejected.
        io_errors: I/O errors (timeouts excluded) seen by the reader thread.
        drops: Samples lost according to device sequence numbers.
        out_of_order: Stale/duplicate packets discarded.
        late: Late arrivals (gap > late factor x expected period).
        last_error: Text of the most recent malformed-packet or I/O error.
    """

    name: str
    running: bool
    finished: bool
    samples: int
    rate_hz: float
    age_s: float
    malformed: int
    io_errors: int
    drops: int
    out_of_order: int
    late: int
    last_error: str | None


def _log_now(count: int) -> bool:
    """Rate-limit repeated warnings: log the first 5 occurrences, then every 1000th."""
    return count <= 5 or count % 1000 == 0


class StreamingSource(ABC, Generic[T]):
    """Base class: one device, one daemon reader thread, one :class:`LatestValue` buffer.

    Subclasses implement ``_open``, ``_read_once`` and ``_close`` and may override
    ``_after_thread_start`` (e.g. to send a start-streaming command and wait for data) and
    ``_interrupt`` (to unblock a pending read during ``stop``).

    Args:
        name: Name used in errors, logs and the thread name.
        expected_rate_hz: Nominal data rate, used by the rate monitor's ``late`` counter.
        rate_window_s: Sliding window of the rate monitor.
        io_backoff_s: Sleep after an I/O error before retrying.
    """

    def __init__(
        self,
        name: str,
        *,
        expected_rate_hz: float | None = None,
        rate_window_s: float = 1.0,
        io_backoff_s: float = 0.05,
    ) -> None:
        self.name = name
        self.buffer: LatestValue[T] = LatestValue(name)
        self.rate = RateMonitor(window_s=rate_window_s, expected_rate_hz=expected_rate_hz)
        self.io_backoff_s = io_backoff_s
        self._stop_event = threading.Event()
        self._thread: threading.Thread | None = None
        self._opened = False
        self._close_deferred = False
        self._finished = False
        self._counter_lock = threading.Lock()
        self._malformed = 0
        self._io_errors = 0
        self._last_error: str | None = None
        self._streamed = False  # a first value was published: errors are logged from then on
        self.errors: deque[tuple[float, str]] = deque(maxlen=32)
        """Most recent (monotonic time, message) error events, newest last."""

    # ----------------------------------------------------------------- subclass hooks
    @abstractmethod
    def _open(self) -> None:
        """Open the device; raise :class:`DeviceOpenError` naming it on failure."""

    @abstractmethod
    def _read_once(self) -> None:
        """Read and publish at most one unit of data; block no longer than a short poll timeout."""

    @abstractmethod
    def _close(self) -> None:
        """Release the device. Called once, after the reader thread has ended (or failed to)."""

    def _after_thread_start(self) -> None:
        """Called in ``start()`` once the thread runs; may raise to abort the start."""

    def _interrupt(self) -> None:
        """Called in ``stop()`` before joining, to unblock a read in progress."""

    # ----------------------------------------------------------------- life cycle
    def start(self) -> Self:
        """Open the device, start the reader thread and return ``self``.

        Raises:
            DeviceOpenError: the device cannot be opened (no thread is started).
            DeviceTimeoutError: a subclass's start-up check saw no data (the source is stopped).
            RuntimeError: the source is already running.
        """
        if self._thread is not None and self._thread.is_alive():
            raise RuntimeError(f"{self.name}: already started")
        self._stop_event.clear()
        self._finished = False
        self._close_deferred = False
        self._open()
        self._opened = True
        self._thread = threading.Thread(target=self._run, name=f"lapwrench-{self.name}", daemon=True)
        self._thread.start()
        try:
            self._after_thread_start()
        except BaseException:
            self.stop()
            raise
        return self

    def stop(self, timeout: float = 2.0) -> None:
        """Stop the reader thread (join up to ``timeout`` s) and release the device. Idempotent."""
        self._stop_event.set()
        if self._opened:
            try:
                self._interrupt()
            except Exception as exc:  # stopping must not fail
                log.debug("%s: interrupt failed: %s", self.name, exc)
        thread = self._thread
        if thread is not None and thread is not threading.current_thread():
            thread.join(timeout)
            if thread.is_alive():
                # Never release a device under a read in progress: the thread closes it on exit.
                log.warning("%s: reader thread did not stop within %.1f s; close deferred", self.name, timeout)
                self._close_deferred = True
                if thread.is_alive():
                    return
                # the thread ended meanwhile and may have missed the flag: close here (idempotent)
        self._close_once()

    def _close_once(self) -> None:
        with self._counter_lock:
            opened, self._opened = self._opened, False
        if opened:
            try:
                self._close()
            except Exception as exc:
                log.warning("%s: close failed: %s", self.name, exc)

    def __enter__(self) -> Self:
        return self.start()

    def __exit__(self, *exc_info: object) -> None:
        self.stop()

    @property
    def running(self) -> bool:
        """True while the reader thread is alive."""
        return self._thread is not None and self._thread.is_alive()

    @property
    def stopping(self) -> bool:
        """True once ``stop()`` was requested (subclasses poll this in long operations)."""
        return self._stop_event.is_set()

    # ----------------------------------------------------------------- consumer API
    def latest(self) -> Sample[T] | None:
        """Latest sample or ``None``; never blocks (see :meth:`LatestValue.get`)."""
        return self.buffer.get()

    def fresh(self, max_age: float, now: float | None = None) -> bool:
        """True if the latest sample is at most ``max_age`` seconds old."""
        return self.buffer.fresh(max_age, now)

    def status(self) -> SourceStatus:
        """Health snapshot (counters, rate, age, last error)."""
        r = self.rate.stats()
        latest = self.buffer.get()
        with self._counter_lock:
            malformed, io_errors, last_error = self._malformed, self._io_errors, self._last_error
        return SourceStatus(
            name=self.name,
            running=self.running,
            finished=self._finished,
            samples=0 if latest is None else latest.seq,
            rate_hz=r.rate_hz,
            age_s=self.buffer.age(),
            malformed=malformed,
            io_errors=io_errors,
            drops=r.drops,
            out_of_order=r.out_of_order,
            late=r.late,
            last_error=last_error,
        )

    # ----------------------------------------------------------------- internals
    def _publish(self, value: T, timestamp: float) -> None:
        """Store ``value`` in the buffer and record the arrival in the rate monitor."""
        self.buffer.put(value, timestamp)
        self.rate.tick(timestamp)
        self._streamed = True

    def _warn(self, n: int, msg: str) -> None:
        """Log the ``n``-th error of a kind, rate-limited, once the device has streamed (module docstring)."""
        if self._streamed and _log_now(n):
            log.warning("%s: %s (total %d)", self.name, msg, n)

    def _record_malformed(self, exc: Exception) -> None:
        msg = f"malformed: {exc}"
        with self._counter_lock:
            self._malformed += 1
            n = self._malformed
            self._last_error = msg
        self.errors.append((time.monotonic(), msg))
        self._warn(n, msg)

    def _record_io_error(self, exc: BaseException) -> None:
        msg = f"I/O error: {type(exc).__name__}: {exc}"
        with self._counter_lock:
            self._io_errors += 1
            n = self._io_errors
            self._last_error = msg
        self.errors.append((time.monotonic(), msg))
        self._warn(n, msg)

    def _run(self) -> None:
        try:
            self._loop()
        finally:
            if self._close_deferred:
                self._close_once()

    def _loop(self) -> None:
        while not self._stop_event.is_set():
            try:
                self._read_once()
            except PacketError as exc:
                self._record_malformed(exc)
            except EndOfStream:
                self._finished = True
                log.info("%s: end of stream", self.name)
                break
            except Exception as exc:
                if self._stop_event.is_set():
                    break  # the device was closed under us by stop()
                self._record_io_error(exc)
                self._stop_event.wait(self.io_backoff_s)
