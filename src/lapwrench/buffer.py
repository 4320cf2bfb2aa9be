"""Latest-value buffers and rate monitoring shared by every sensor driver and the loop's sources.

It imports nothing from lapwrench, so both the drivers (world layer) and :mod:`lapwrench.sources`
(loop layer) can use it.

The 1 kHz control loop must never wait for a sensor. Every driver therefore runs its own reader
thread that *publishes* into a :class:`LatestValue`; the control loop only *peeks* at the most
recent :class:`Sample` and decides, from its timestamp, whether the data is fresh enough to use.

Design notes
------------
* A :class:`Sample` is immutable (frozen dataclass). ``put`` builds a new one and swaps a single
  reference; ``get`` reads that reference without taking any lock. Reading and writing one object
  reference is atomic in CPython (and in the free-threaded build), so a reader sees either the old
  or the new sample, never a torn one. Writers serialise on a lock only to keep the sequence number
  strictly increasing when several threads publish.
* Timestamps are ``time.monotonic()`` seconds taken on arrival (host clock, not the device clock),
  so they are directly comparable with the control loop's own ``time.monotonic()``.
* Values stored in a buffer must be treated as read-only. The drivers publish NumPy arrays with
  ``flags.writeable = False`` so an accidental in-place edit by a consumer raises.
* :class:`RateMonitor` estimates the arrival rate over a sliding window and counts drops (gaps in
  a device sequence number), out-of-order/duplicate packets and late arrivals (an inter-arrival
  gap longer than ``late_factor`` times the expected period).
"""

from __future__ import annotations

import math
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Generic, Protocol, TypeVar

__all__ = ["LatestValue", "RateMonitor", "RateStats", "Sample", "SampleBuffer"]

T = TypeVar("T")


@dataclass(frozen=True, slots=True)
class Sample(Generic[T]):
    """One published value.

    Attributes:
        value: The payload (treat as read-only).
        timestamp: ``time.monotonic()`` seconds at which the value was received on the host.
        seq: Buffer sequence number, 1 for the first ``put`` and strictly increasing afterwards.
    """

    value: T
    timestamp: float
    seq: int

    def age(self, now: float | None = None) -> float:
        """Seconds elapsed since ``timestamp`` (``now`` defaults to ``time.monotonic()``)."""
        return (time.monotonic() if now is None else now) - self.timestamp


class SampleBuffer(Protocol[T]):
    """What a reader of the latest sample needs: a :class:`LatestValue`, or another process's slot
    (:class:`~lapwrench.hardware.rt.inputs.ShmInput`)."""

    def get(self) -> Sample[T] | None: ...


class LatestValue(Generic[T]):
    """Thread-safe single-slot buffer holding only the most recent :class:`Sample`.

    ``get``, ``age`` and ``fresh`` never block: they read one reference. ``put`` takes a short,
    uncontended lock (one writer per buffer in practice). ``wait_newer`` is a blocking helper for
    start-up and tests; never call it from the control loop.
    """

    __slots__ = ("_cond", "_name", "_sample", "_seq", "_waiting")

    def __init__(self, name: str = "", lock: threading.Lock | None = None) -> None:
        """``lock`` serialises the writers (a new one unless given; readers never take it)."""
        self._name = name
        self._sample: Sample[T] | None = None
        self._seq = 0
        self._waiting = 0  # threads in wait_newer (under the lock): put notifies only when there are any
        self._cond = threading.Condition(threading.Lock() if lock is None else lock)

    @property
    def name(self) -> str:
        """Human-readable name of the source feeding this buffer."""
        return self._name

    def put(self, value: T, timestamp: float | None = None) -> Sample[T]:
        """Publish ``value`` (timestamped now unless ``timestamp`` is given) and return the sample."""
        ts = time.monotonic() if timestamp is None else float(timestamp)
        with self._cond:
            self._seq += 1
            sample = Sample(value, ts, self._seq)
            self._sample = sample  # single atomic reference swap; readers never lock
            if self._waiting:  # notify_all's own cost, every sample of a 1 kHz device, only when someone waits
                self._cond.notify_all()
        return sample

    def get(self) -> Sample[T] | None:
        """Return the latest sample, or ``None`` if nothing was published yet. Never blocks."""
        return self._sample

    def age(self, now: float | None = None) -> float:
        """Age in seconds of the latest sample; ``math.inf`` if there is none."""
        sample = self._sample
        if sample is None:
            return math.inf
        return sample.age(now)

    def fresh(self, max_age: float, now: float | None = None) -> bool:
        """True if a sample exists and it is at most ``max_age`` seconds old."""
        return self.age(now) <= max_age

    def get_fresh(self, max_age: float, now: float | None = None) -> Sample[T] | None:
        """The latest sample if it is at most ``max_age`` s old, else ``None``. Never blocks.

        This is the call a control loop makes each cycle: ``None`` means "switch this source's
        wrench off".
        """
        sample = self._sample
        if sample is None or sample.age(now) > max_age:
            return None
        return sample

    def clear(self) -> None:
        """Forget the latest sample (the sequence number keeps counting)."""
        with self._cond:
            self._sample = None

    def wait_newer(self, seq: int = 0, timeout: float | None = None) -> Sample[T] | None:
        """Block until a sample with ``sample.seq > seq`` exists; return it, or ``None`` on timeout.

        For start-up and tests only; the control loop must use :meth:`get`.
        """
        deadline = None if timeout is None else time.monotonic() + timeout
        with self._cond:
            self._waiting += 1
            try:
                while self._sample is None or self._sample.seq <= seq:
                    remaining = None if deadline is None else deadline - time.monotonic()
                    if remaining is not None and remaining <= 0:
                        return None
                    self._cond.wait(remaining)
                return self._sample
            finally:
                self._waiting -= 1

    def __repr__(self) -> str:
        s = self._sample
        return f"LatestValue({self._name!r}, seq={0 if s is None else s.seq})"


@dataclass(frozen=True, slots=True)
class RateStats:
    """Snapshot of a :class:`RateMonitor`.

    Attributes:
        rate_hz: Arrival rate estimated over the sliding window (0 when fewer than two arrivals).
        count: Total arrivals recorded by ``tick``.
        drops: Samples missing according to gaps in the device sequence number.
        out_of_order: Arrivals whose sequence number did not advance (duplicates, reordering).
        late: Inter-arrival gaps longer than ``late_factor`` x the expected period.
        last_time: Monotonic time of the last arrival (``None`` if none).
        resyncs: Far sequence jumps confirmed by the next packet (outages, device restarts).
    """

    rate_hz: float
    count: int
    drops: int
    out_of_order: int
    late: int
    last_time: float | None
    resyncs: int = 0


class RateMonitor:
    """Sliding-window rate estimator with drop, out-of-order and late counters.

    Args:
        window_s: Length of the sliding window in seconds.
        expected_rate_hz: Nominal rate; enables the ``late`` counter when given.
        late_factor: An arrival is *late* when the gap since the previous one exceeds
            ``late_factor / expected_rate_hz``.
        seq_bits: Width of the device sequence counter (wrap-around handling).
        restart_gap: A backwards jump larger than this many counts may be a device stream restart
            (the counter was reset) rather than an out-of-order packet (see :meth:`check_seq`).
        resync_gap: A forward jump larger than this many counts may be an outage or a corrupt
            packet (see :meth:`check_seq`).
        max_events: Cap on timestamps kept in the window (bounds memory at very high rates).

    All methods are thread-safe; each holds an internal lock for a few microseconds.
    """

    def __init__(
        self,
        window_s: float = 1.0,
        expected_rate_hz: float | None = None,
        late_factor: float = 3.0,
        seq_bits: int = 32,
        restart_gap: int = 1000,
        max_events: int = 20000,
        resync_gap: int = 100,
    ) -> None:
        if window_s <= 0:
            raise ValueError("window_s must be > 0")
        if expected_rate_hz is not None and expected_rate_hz <= 0:
            raise ValueError("expected_rate_hz must be > 0")
        self.window_s = float(window_s)
        self.expected_rate_hz = expected_rate_hz
        self.late_factor = float(late_factor)
        self._mod = 1 << seq_bits
        self._restart_gap = restart_gap
        self._resync_gap = resync_gap
        self._pending_seq: int | None = None
        self._jump: tuple[int, int] | None = None  # (sequence before, drops counted) of a provisional jump
        self._anchored = False  # two packets in order seen since the sequence was (re)started
        self._resyncs = 0
        self._times: deque[float] = deque(maxlen=max_events)
        self._lock = threading.Lock()
        self._count = 0
        self._drops = 0
        self._out_of_order = 0
        self._late = 0
        self._last_time: float | None = None
        self._last_seq: int | None = None

    def check_seq(self, seq: int) -> bool:
        """Account for device sequence number ``seq``; return False if the packet is to be discarded.

        A forward step of ``k <= resync_gap`` counts adds ``k - 1`` drops. A duplicate or a small
        backwards step (``<= restart_gap``) counts as out-of-order. A *far* jump (forward beyond
        ``resync_gap``, or backward beyond ``restart_gap``) is either a stream resync (an outage, a
        device restart) or a corrupt packet; it is accepted only when the next packet continues from
        it (it then counts one resync, not the packets in between as drops). Until then it is
        discarded and the stream goes on from the old number, so one bad packet costs one packet.

        A near forward jump (``1 < k <= resync_gap``) is accepted at once, but provisionally: when
        the very next packet continues the sequence from *before* the jump, the jumped packet was
        the odd one out (a corrupt sequence number, or one packet reordered) and the stream goes on
        from the older number, its drops taken back. Without this, one packet numbered ``last + 90``
        would discard the next 89 good ones as out-of-order. Likewise the first packet (after
        :meth:`forget_seq`) anchors nothing until the next one follows it: a corrupt first number
        would otherwise discard up to ``restart_gap`` good packets.
        """
        with self._lock:
            last = self._last_seq
            jump, self._jump = self._jump, None
            if last is None:
                self._last_seq, self._anchored = seq, False
                return True
            diff = self._signed(seq - last)
            if 1 <= diff <= self._resync_gap:
                self._drops += diff - 1
                self._last_seq, self._pending_seq, self._anchored = seq, None, True
                if diff > 1:
                    self._jump = (last, diff - 1)
                return True
            if not self._anchored:  # no two packets in order yet: the first number is no better than this one
                self._last_seq = seq
                return True
            if jump is not None and 1 <= self._signed(seq - jump[0]) < self._signed(last - jump[0]):
                before, counted = jump  # the jumped packet was the outlier: go on from before it
                self._drops += self._signed(seq - before) - 1 - counted
                self._last_seq, self._pending_seq = seq, None
                return True
            if diff <= 0 and -diff <= self._restart_gap:
                self._out_of_order += 1
                return False
            pending = self._pending_seq
            if pending is not None and 1 <= self._signed(seq - pending) <= self._resync_gap:
                self._last_seq, self._pending_seq = seq, None
                self._resyncs += 1
                return True
            self._pending_seq = seq
            self._out_of_order += 1
            return False

    def _signed(self, d: int) -> int:
        d %= self._mod
        return d - self._mod if d >= self._mod // 2 else d

    def tick(self, now: float | None = None) -> None:
        """Record one accepted arrival at ``now`` (default ``time.monotonic()``)."""
        t = time.monotonic() if now is None else now
        with self._lock:
            if (
                self.expected_rate_hz is not None
                and self._last_time is not None
                and t - self._last_time > self.late_factor / self.expected_rate_hz
            ):
                self._late += 1
            self._times.append(t)
            self._count += 1
            self._last_time = t
            self._prune(t)

    def forget_seq(self) -> None:
        """Forget the last device sequence number (call when the device stream is restarted)."""
        with self._lock:
            self._last_seq = self._pending_seq = self._jump = None

    def add_drops(self, n: int = 1) -> None:
        """Add ``n`` drops detected by other means (e.g. a lost camera frame)."""
        with self._lock:
            self._drops += n

    def _prune(self, now: float) -> None:
        horizon = now - self.window_s
        times = self._times
        while times and times[0] < horizon:
            times.popleft()

    def rate(self, now: float | None = None) -> float:
        """Arrival rate in Hz over the window ending at ``now``; decays to 0 when arrivals stop."""
        t = time.monotonic() if now is None else now
        with self._lock:
            self._prune(t)
            n = len(self._times)
            if n < 2:
                return 0.0
            span = t - self._times[0]
            return (n - 1) / span if span > 0 else 0.0

    def stats(self, now: float | None = None) -> RateStats:
        """Consistent snapshot of the rate and all counters."""
        rate = self.rate(now)
        with self._lock:
            return RateStats(
                rate_hz=rate,
                count=self._count,
                drops=self._drops,
                out_of_order=self._out_of_order,
                late=self._late,
                last_time=self._last_time,
                resyncs=self._resyncs,
            )

    def reset(self) -> None:
        """Clear the window, the counters and the remembered sequence number."""
        with self._lock:
            self._times.clear()
            self._count = self._drops = self._out_of_order = self._late = self._resyncs = 0
            self._last_time = None
            self._last_seq = self._pending_seq = self._jump = None
