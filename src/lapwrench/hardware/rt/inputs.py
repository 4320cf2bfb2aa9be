"""The child's inputs from shared memory: a seqlock slot read as a latest-value buffer."""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from lapwrench.buffer import Sample
from lapwrench.hardware.rt.bus import MAX_POINTS, TACTILE_N
from lapwrench.hardware.shm import SeqlockSlot
from lapwrench.sensors import InstrumentObservation


@dataclass(frozen=True, slots=True)
class _Values:
    values: np.ndarray


class ShmInput:
    """A shared-memory slot seen by :class:`~lapwrench.hardware.runner.ControlLoop` as a
    latest-value buffer (``get_fresh``). :meth:`refresh` reads and checks the slot once per cycle
    (in the loop's ``after_command``); it returns a message when the slot holds corrupt data."""

    def __init__(
        self, slot: SeqlockSlot, kind: str, clock: Callable[[], float] = time.monotonic, *, registered: bool = False
    ) -> None:
        """``registered``: the slot of a registered input (:mod:`lapwrench.inputs`) named ``kind``, whose
        value is its array as written (range checks are the validator's, with the input's spec)."""
        if not registered and kind not in ("tactile", "instruments"):
            raise ValueError(f"unknown shared input {kind!r}")
        self.slot, self.kind, self.clock, self.registered = slot, kind, clock, registered
        self._buf = np.empty_like(slot.data)
        # the sequence number read as a Python int, without numpy's item access (numpy's stubs give arrays the
        # buffer protocol only from Python 3.12 on)
        self._hdr: memoryview[int] = memoryview(slot.hdr)  # type: ignore[arg-type]
        self._seq = 0
        self._sample: Sample[Any] | None = None
        self.dead = False
        self.torn = 0

    @property
    def name(self) -> str:
        return self.kind

    def kill(self) -> None:
        """Its writer is gone: read as stale from now on."""
        self.dead = True
        self._sample = None

    def refresh(self, now: float) -> str | None:
        """Read the slot if it holds a new sample (checked, then published to :meth:`get`); a message when
        it is corrupt. An unchanged sequence number (most cycles: the writers publish at 25 to 200 Hz) costs
        one read of it, no copy of the payload."""
        if self.dead or self._hdr[0] == self._seq:  # an even number already read: nothing new, nothing torn
            return None
        r = self.slot.read_into(self._buf)
        if r is None:
            if self.slot.seq & 1:
                self.torn += 1
            return None
        seq, stamp, count = r
        if seq == self._seq:
            return None
        self._seq = seq
        b = self._buf
        problem = None
        # compared with the clock read now, not the cycle's start: a writer may publish while this
        # process is preempted between the two (seen under load), which is no corruption
        if not (math.isfinite(stamp) and stamp <= self.clock() + 0.005):
            problem = f"sample stamp {stamp!r} is not a past monotonic time"
        elif self.registered:
            if count != b.shape[0]:  # a whole reading is written: every row of its shape
                problem = f"{count} rows, not {b.shape[0]}"
        elif self.kind == "tactile":
            if count != TACTILE_N or not _all_finite(b):
                problem = f"{count} values, non-finite: {int(np.sum(~np.isfinite(b)))}"
        elif not 0 <= count <= MAX_POINTS:
            problem = f"point count {count} outside [0, {MAX_POINTS}]"
        elif not _all_finite(b[:count]):
            problem = "non-finite image point"
        if problem is not None:
            self._sample = None
            return f"{self.kind} slot: {problem}"
        if self.registered:
            value: Any = b.copy()
        elif self.kind == "tactile":
            value = _Values(b.copy())
        else:
            value = InstrumentObservation(b[:count].copy(), stamp)
        self._sample = Sample(value, stamp, seq)
        return None

    def get(self) -> Sample[Any] | None:
        return self._sample

    def get_fresh(self, max_age: float, now: float | None = None) -> Sample[Any] | None:
        s = self._sample
        if s is None or (time.monotonic() if now is None else now) - s.timestamp > max_age:
            return None
        return s


def _all_finite(a: np.ndarray) -> bool:
    """No NaN or infinity in ``a``. Its sum is finite only then, unless finite values overflow it: the sum
    first (one reduction), the element-wise check only when the sum is not finite."""
    return math.isfinite(a.sum()) or bool(np.isfinite(a).all())
