"""When a datagram arrived: the kernel's receive stamp (Linux ``SO_TIMESTAMPNS``), on the reader's clock.

A datagram taken off a socket late (the reader was busy, the process stalled) is not new, and stamping
it with the time it was read makes old data look fresh. Worse, after a stall longer than the socket's
buffer holds (about 256 F/T datagrams by default), the kernel has kept the *oldest* datagrams and
dropped the newer ones, so the newest datagram read can be hundreds of milliseconds old.

The kernel stamps every datagram as it arrives. :func:`enable` asks for that stamp, :func:`recv_stamped`
reads it with the datagram (``recvmsg`` ancillary data), and :func:`on_clock` puts it on the reader's
clock: arrival = now - (wall-clock now - kernel stamp). Where the kernel gives no stamp (not Linux, the
option refused), the read time stands, as before. Linux switches arrival stamping on lazily: the first
socket that asks schedules a deferred work item, and until it has run (on a busy machine, tens of ms)
a datagram is stamped when it is read, i.e. as before; the F/T drivers open their socket, tare and
start before the loop reads them, so the loop sees arrival stamps.
"""

from __future__ import annotations

import socket
import struct
import sys

SO_TIMESTAMPNS = 35
"""Linux's ``SO_TIMESTAMPNS`` (``SO_TIMESTAMPNS_OLD`` in asm-generic/socket.h; the ancillary message's
type ``SCM_TIMESTAMPNS`` has the same value). Python's socket module does not name it."""
_TIMESPEC = struct.Struct("@ll")  # struct timespec of that option: time_t and long, native size
ANC_SIZE = socket.CMSG_SPACE(_TIMESPEC.size)


def enable(sock: socket.socket) -> bool:
    """Ask the kernel to stamp every datagram ``sock`` receives; False where it cannot (then
    :func:`recv_stamped` gives no stamp)."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    except OSError:
        return False
    return True


def recv_stamped(sock: socket.socket, bufsize: int) -> tuple[bytes, float | None]:
    """One datagram and the wall-clock time (s, ``time.time()``'s clock) the kernel stamped on its
    arrival, None without a stamp. Raises what ``sock.recvmsg`` raises."""
    data, ancdata, _flags, _addr = sock.recvmsg(bufsize, ANC_SIZE)
    for level, kind, payload in ancdata:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS and len(payload) >= _TIMESPEC.size:
            sec, nsec = _TIMESPEC.unpack_from(payload)
            return data, sec + nsec * 1e-9
    return data, None


def on_clock(kernel_stamp: float | None, now: float, wall_now: float) -> float:
    """The arrival time on the reader's clock: ``now`` (that clock, read at ``wall_now`` on the wall
    clock) less the datagram's age ``wall_now - kernel_stamp``; ``now`` without a stamp. A negative
    age (the wall clock stepped back since) counts as none: never later than ``now``."""
    if kernel_stamp is None:
        return now
    age = wall_now - kernel_stamp
    return now - age if age > 0.0 else now
