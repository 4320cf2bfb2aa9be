"""The processes the real-time child depends on and their heartbeats (pidfd + heartbeat age)."""

from __future__ import annotations

import contextlib
import math
import os
import select
import time
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class PeerSpec:
    """A process the child depends on: its heartbeat stamp index on the bus, the heartbeat age
    that counts as a hang (s), and its pid (watched through a pidfd; ``None``: heartbeat only)."""

    name: str
    beat: int
    timeout: float
    pid: int | None = None


class PeerWatch:
    """Checks every peer each cycle: exited (pidfd readable) or heartbeat too old."""

    def __init__(self, beats: np.ndarray, peers: list[PeerSpec]) -> None:
        self.beats = beats
        # the stamps read as Python floats, without numpy's item access (numpy's stubs give arrays the buffer
        # protocol only from Python 3.12 on)
        self._beat: memoryview[float] = memoryview(beats)  # type: ignore[arg-type]
        self.peers = peers
        self._poll = select.poll()
        self._fd_peer: dict[int, PeerSpec] = {}
        self._kill_check: list[PeerSpec] = []
        for p in peers:
            if p.pid is None:
                continue
            try:
                fd = os.pidfd_open(p.pid)
            except (AttributeError, OSError):  # no pidfd (old kernel) or already gone: checked by kill(pid, 0),
                self._kill_check.append(p)  # which reports a peer gone already at its first check
                continue
            self._fd_peer[fd] = p
            self._poll.register(fd, select.POLLIN)
        self.armed_at = time.monotonic()

    def arm(self, now: float) -> None:
        """Heartbeats count from now on (the start-up is not a hang)."""
        self.armed_at = now

    def check(self, now: float) -> tuple[str, PeerSpec] | None:
        if self._fd_peer:
            for fd, _ev in self._poll.poll(0):
                p = self._fd_peer[fd]
                return f"{p.name} process (pid {p.pid}) exited", p
        for p in self._kill_check:
            if not _pid_alive(p.pid):  # type: ignore[arg-type]
                return f"{p.name} process (pid {p.pid}) exited", p
        beat, armed = self._beat, self.armed_at
        for p in self.peers:
            stamp = beat[p.beat]
            if now - (stamp if stamp > armed else armed) > p.timeout:
                age = now - stamp if stamp > 0 else math.inf
                return f"no heartbeat from the {p.name} for {age * 1e3:.0f} ms (> {p.timeout * 1e3:.0f} ms): hung", p
        return None

    def forget(self, peer: PeerSpec) -> None:
        """Stop watching ``peer`` (reported already): the others are checked again from the next cycle."""
        self.peers = [p for p in self.peers if p is not peer]
        self._kill_check = [p for p in self._kill_check if p is not peer]
        for fd, p in list(self._fd_peer.items()):
            if p is peer:
                self._poll.unregister(fd)
                del self._fd_peer[fd]
                with contextlib.suppress(OSError):
                    os.close(fd)

    def close(self) -> None:
        for fd in self._fd_peer:
            with contextlib.suppress(OSError):
                os.close(fd)
        self._fd_peer = {}


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True
