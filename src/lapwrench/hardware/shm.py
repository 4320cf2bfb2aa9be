"""Shared-memory plumbing between the real-time control process and its helpers.

Everything here is lock-free and never blocks the writer:

* :class:`SeqlockSlot`: a latest-value slot (one writer, any number of readers). The writer makes
  the sequence number odd, writes the payload, the sample's timestamp and its row count, then
  makes the sequence even again; a reader copies the payload between two reads of the sequence
  and retries (a few times) when it changed or was odd. A reader therefore never sees a torn
  value; a writer that died in the middle of a write leaves the sequence odd and the slot reads
  as *absent* (stale) from then on.
* :class:`Ring`: a bounded single-producer/single-consumer ring of fixed-size rows (log records,
  events). The producer drops (and counts) a row when the ring is full, so a slow consumer never
  blocks it.
* :class:`Bus`: one :class:`multiprocessing.shared_memory.SharedMemory` block holding named
  regions (control words, heartbeats, slots, rings) at fixed offsets computed from a
  :class:`Layout`, so every process maps the same views. Attaching checks the block's size against
  the layout and refuses a truncated block with :class:`ShmError`.

Timestamps are ``time.monotonic()`` seconds: on Linux that is ``CLOCK_MONOTONIC``, one clock for
every process on the machine, so a reader in another process can age a sample directly.

Memory ordering: the protocol relies on stores becoming visible in program order and loads not
being reordered with each other, which holds on x86-64 (TSO), where every 8-byte aligned integer
store here is a single store. On a weakly ordered CPU (ARM) the seqlock and the ring indices
would need explicit barriers.
"""

from __future__ import annotations

import contextlib
import math
import struct
import time
from dataclasses import dataclass, field
from multiprocessing import shared_memory
from typing import Any

import numpy as np

__all__ = ["Bus", "Layout", "Ring", "SeqlockSlot", "ShmError", "pack_event", "unpack_event"]

_ALIGN = 64


class ShmError(RuntimeError):
    """A shared-memory block is missing, truncated or does not match the expected layout."""


@dataclass
class Layout:
    """Named regions of a shared-memory block: ``add(name, dtype, shape)`` then :attr:`size`."""

    regions: dict[str, tuple[int, str, tuple[int, ...]]] = field(default_factory=dict)
    size: int = 0

    def add(self, name: str, dtype: Any, shape: tuple[int, ...]) -> Layout:
        if name in self.regions:
            raise ValueError(f"region {name!r} defined twice")
        dt = np.dtype(dtype)
        offset = -(-self.size // _ALIGN) * _ALIGN
        nbytes = int(np.prod(shape, dtype=np.int64)) * dt.itemsize
        self.regions[name] = (offset, dt.str, tuple(int(s) for s in shape))
        self.size = offset + nbytes
        return self

    def slot(self, name: str, dtype: Any, shape: tuple[int, ...]) -> Layout:
        """Regions of one :class:`SeqlockSlot`: a header and its payload."""
        return self.add(f"{name}.hdr", np.int64, (4,)).add(f"{name}.stamp", np.float64, (1,)).add(
            f"{name}.data", dtype, shape
        )

    def ring(self, name: str, dtype: Any, rows: int, width: int) -> Layout:
        """Regions of one :class:`Ring`: indices and ``rows`` rows of ``width`` items."""
        if rows < 1 or width < 1:
            raise ValueError("a ring needs at least one row of one item")
        return self.add(f"{name}.idx", np.int64, (4,)).add(f"{name}.rows", dtype, (rows, width))


def _attach_untracked(name: str) -> shared_memory.SharedMemory:
    """Attach without registering the block with the resource tracker (Python < 3.13 registers
    every attach, and the tracker would then unlink the creator's block when an attaching process
    exits); the creator alone owns and unlinks it."""
    from multiprocessing import resource_tracker

    original = resource_tracker.register

    def register(rname: str, rtype: str) -> None:
        if rtype != "shared_memory":
            original(rname, rtype)

    resource_tracker.register = register  # type: ignore[assignment]
    try:
        return shared_memory.SharedMemory(name=name, create=False)
    finally:
        resource_tracker.register = original


class Bus:
    """A shared-memory block with the views of a :class:`Layout`.

    Use :meth:`create` in the owning process and :meth:`attach` (by name) in the others; only the
    creator unlinks the block (:meth:`close`).
    """

    def __init__(self, shm: shared_memory.SharedMemory, layout: Layout, owner: bool) -> None:
        self.shm = shm
        self.layout = layout
        self.owner = owner
        self.views: dict[str, np.ndarray] = {}
        for name, (offset, dt, shape) in layout.regions.items():
            self.views[name] = np.ndarray(shape, dtype=np.dtype(dt), buffer=shm.buf, offset=offset)

    @property
    def name(self) -> str:
        return self.shm.name

    @classmethod
    def create(cls, layout: Layout) -> Bus:
        shm = shared_memory.SharedMemory(create=True, size=max(layout.size, 1))
        assert shm.buf is not None  # None only once closed
        np.frombuffer(shm.buf, dtype=np.uint8)[:] = 0
        return cls(shm, layout, owner=True)

    @classmethod
    def attach(cls, name: str, layout: Layout) -> Bus:
        """Map an existing block; :class:`ShmError` if it is absent or smaller than ``layout``."""
        try:
            shm = _attach_untracked(name)
        except FileNotFoundError as exc:
            raise ShmError(f"shared memory block {name!r} does not exist") from exc
        if shm.size < layout.size:
            size = shm.size
            shm.close()
            raise ShmError(f"shared memory block {name!r} has {size} bytes, the layout needs {layout.size}")
        return cls(shm, layout, owner=False)

    def __getitem__(self, name: str) -> np.ndarray:
        return self.views[name]

    def slot(self, name: str) -> SeqlockSlot:
        return SeqlockSlot(self.views[f"{name}.hdr"], self.views[f"{name}.stamp"], self.views[f"{name}.data"])

    def ring(self, name: str) -> Ring:
        return Ring(self.views[f"{name}.idx"], self.views[f"{name}.rows"])

    def close(self) -> None:
        """Drop the views, unmap, and unlink if this process created the block. Idempotent."""
        self.views = {}
        with contextlib.suppress(BufferError, OSError):
            self.shm.close()
        if self.owner:
            self.owner = False
            with contextlib.suppress(FileNotFoundError):
                self.shm.unlink()


class SeqlockSlot:
    """Latest-value slot in shared memory (see the module docstring).

    ``hdr`` = ``[seq, count, writes, reserved]`` (int64), ``stamp`` = ``[t]`` (float64, monotonic
    seconds of the *sample*), ``data`` the payload; ``count`` is how many leading rows of the
    payload are valid (e.g. the number of detected instrument points).
    """

    __slots__ = ("data", "hdr", "stamp")

    def __init__(self, hdr: np.ndarray, stamp: np.ndarray, data: np.ndarray) -> None:
        self.hdr, self.stamp, self.data = hdr, stamp, data

    @property
    def capacity(self) -> int:
        return int(self.data.shape[0])

    @property
    def seq(self) -> int:
        return int(self.hdr[0])

    def write(self, value: Any, stamp: float, count: int | None = None) -> int:
        """Publish ``value`` (the first ``count`` rows, default: the whole payload); returns the new
        (even) sequence number. One writer per slot."""
        hdr = self.hdr
        s = int(hdr[0])
        if s & 1:  # a previous writer died mid-write: start from the next even number
            s += 1
        hdr[0] = s + 1
        if count is None:
            self.data[...] = value
            n = self.capacity
        else:
            n = int(count)
            if n:
                self.data[:n] = value
        self.stamp[0] = stamp
        hdr[1] = n
        hdr[2] += 1
        hdr[0] = s + 2
        return s + 2

    def read_into(self, out: np.ndarray, retries: int = 4) -> tuple[int, float, int] | None:
        """Copy the payload into ``out``; ``(seq, stamp, count)``, or ``None`` when nothing was
        published yet or the writer was mid-write on every try (a torn or abandoned write)."""
        hdr = self.hdr
        for _ in range(retries):
            s1 = int(hdr[0])
            if s1 == 0:
                return None
            if s1 & 1:
                continue
            np.copyto(out, self.data)
            stamp = float(self.stamp[0])
            count = int(hdr[1])
            if int(hdr[0]) == s1:
                return s1, stamp, count
        return None


class Ring:
    """Bounded SPSC ring of rows: ``idx`` = ``[head (rows written), tail (rows read), dropped, spare]``.

    The producer calls :meth:`reserve` (a row view to fill, or ``None`` when full: counted as a
    drop), fills it, then :meth:`commit`. The consumer calls :meth:`pending` and :meth:`take`.
    """

    __slots__ = ("idx", "n", "rows")

    def __init__(self, idx: np.ndarray, rows: np.ndarray) -> None:
        self.idx, self.rows = idx, rows
        self.n = int(rows.shape[0])

    def reserve(self) -> np.ndarray | None:
        h = int(self.idx[0])
        if h - int(self.idx[1]) >= self.n:
            self.idx[2] += 1
            return None
        return self.rows[h % self.n]

    def commit(self) -> None:
        self.idx[0] += 1

    def push(self, row: Any) -> bool:
        r = self.reserve()
        if r is None:
            return False
        r[...] = row
        self.commit()
        return True

    @property
    def dropped(self) -> int:
        return int(self.idx[2])

    def pending(self) -> int:
        return int(self.idx[0]) - int(self.idx[1])

    def take(self, limit: int | None = None) -> np.ndarray:
        """Copy out (and release) up to ``limit`` pending rows, oldest first."""
        h, t = int(self.idx[0]), int(self.idx[1])
        k = h - t if limit is None else min(h - t, limit)
        if k <= 0:
            return self.rows[:0].copy()
        i = np.arange(t, t + k) % self.n
        out = self.rows[i].copy()
        self.idx[1] = t + k
        return out


# -- events as fixed-size byte rows ---------------------------------------------------------------
_EV_HEAD = struct.Struct("<dHH")


def pack_event(row: np.ndarray, t: float, kind: str, message: str) -> None:
    """Write ``(t, kind, message)`` into a uint8 row (UTF-8, truncated to fit)."""
    width = row.shape[0]
    k = kind.encode()[:64]
    room = width - _EV_HEAD.size - len(k)
    m = message.encode()
    if len(m) > room:
        m = m[: max(0, room - 3)].decode(errors="ignore").encode() + b"..."
    buf = _EV_HEAD.pack(t if math.isfinite(t) else -1.0, len(k), len(m)) + k + m
    row[: len(buf)] = np.frombuffer(buf, dtype=np.uint8)


def unpack_event(row: np.ndarray) -> tuple[float, str, str]:
    b = row.tobytes()
    t, nk, nm = _EV_HEAD.unpack_from(b)
    o = _EV_HEAD.size
    return t, b[o : o + nk].decode(errors="replace"), b[o + nk : o + nk + nm].decode(errors="replace")


def monotonic() -> float:
    """The clock every stamp on a bus uses."""
    return time.monotonic()
