"""lapwrench.drivers.simulated_hex: the loopback F/T box ``run --dry-run`` and the F/T tests talk to
speaks the RDT/EtherDAQ protocol: start, stream, stop, bias, and the faults it can inject. Talked to
here with a plain UDP socket, as the device would be."""

from __future__ import annotations

import os
import socket
import sys
import threading
from collections.abc import Iterator

import pytest
from helpers import thread_policy

from lapwrench.drivers.ft.wire import CMD_BIAS, CMD_START_REALTIME, CMD_STOP, FTRecord, pack_request, unpack_record
from lapwrench.drivers.simulated_hex import SimulatedHexBox


@pytest.fixture
def client() -> Iterator[socket.socket]:
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(2.0)
    yield s
    s.close()


def records(s: socket.socket, n: int) -> list[FTRecord]:
    return [unpack_record(s.recv(2048)) for _ in range(n)]


def drain(s: socket.socket) -> list[FTRecord]:
    """The records still arriving within 50 ms of silence."""
    out = []
    s.settimeout(0.05)
    try:
        while True:
            out.append(unpack_record(s.recv(2048)))
    except TimeoutError:
        pass
    s.settimeout(2.0)
    return out


def test_it_streams_its_counts_after_the_start_command(client: socket.socket) -> None:
    with SimulatedHexBox(rate_hz=1000.0, counts=(1, -2, 3, 4, 5, -6)) as box:
        assert box.address[0] == "127.0.0.1" and box.port > 0 and not box.streaming
        client.sendto(pack_request(CMD_START_REALTIME), box.address)
        got = records(client, 5)
        assert [r.sequence for r in got] == [1, 2, 3, 4, 5] and [r.ft_sequence for r in got] == [0, 1, 2, 3, 4]
        assert all(r.counts == (1, -2, 3, 4, 5, -6) and r.status == 0 for r in got) and box.streaming
        client.sendto(pack_request(CMD_STOP), box.address)
        drain(client)
        assert not box.streaming and box.commands[:2] == [(CMD_START_REALTIME, 0), (CMD_STOP, 0)]


def test_the_bias_command_zeroes_the_current_counts(client: socket.socket) -> None:
    with SimulatedHexBox(rate_hz=1000.0, counts=(10, 0, 0, 0, 0, 0)) as box:
        client.sendto(pack_request(CMD_START_REALTIME), box.address)
        assert records(client, 1)[0].counts[0] == 10
        box.pause()  # each change lands between records: no record in flight is read as the next one
        drain(client)
        client.sendto(pack_request(CMD_BIAS, 1), box.address)
        while len(box.commands) < 2:  # the box handles requests while paused
            drain(client)
        box.resume()
        assert records(client, 1)[0].counts == (0,) * 6
        box.pause()
        drain(client)
        box.counts[0] = 25  # a new load, written in place: the bias keeps its own copy of the old counts
        box.resume()
        assert records(client, 1)[0].counts[0] == 15


def test_it_injects_gaps_duplicates_and_raw_datagrams(client: socket.socket) -> None:
    with SimulatedHexBox(rate_hz=1000.0) as box:
        client.sendto(pack_request(CMD_START_REALTIME), box.address)
        got = records(client, 1)
        box.pause()  # set the faults up while nothing is sent
        last = (got + drain(client))[-1].sequence
        box.skip(3)
        box.duplicate(1)
        box.inject([b"junk"])
        box.resume()
        raw = [client.recv(2048) for _ in range(3)]
        assert raw[0] == b"junk"  # injected before the next record
        assert [unpack_record(r).sequence for r in raw[1:]] == [last, last + 4]  # a duplicate, then 3 lost


def test_a_paused_box_goes_silent_and_a_bad_request_is_ignored(client: socket.socket) -> None:
    with SimulatedHexBox(rate_hz=1000.0) as box:
        client.sendto(b"\x00\x01", box.address)  # not a request
        client.sendto(pack_request(CMD_START_REALTIME), box.address)
        records(client, 1)
        box.pause()
        drain(client)
        client.settimeout(0.1)
        with pytest.raises(TimeoutError):
            client.recv(2048)
        client.settimeout(2.0)
        box.resume()
        assert records(client, 1)
    assert box.bad_requests == 1 and box.sent >= 2  # counted once the box's thread has ended


def _fifo_threads() -> set[int]:
    """The ids of this process's threads that run at SCHED_FIFO."""
    out = set()
    for tid in os.listdir("/proc/self/task"):
        try:
            if thread_policy(int(tid))[0] == os.SCHED_FIFO:
                out.add(int(tid))
        except OSError:  # the thread ended meanwhile
            pass
    return out


def _fifo_permitted() -> bool:
    """Whether this process may raise a thread to SCHED_FIFO (root, or CAP_SYS_NICE)."""
    result: list[bool] = []

    def probe() -> None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(1))
            result.append(True)
        except OSError:
            result.append(False)

    t = threading.Thread(target=probe)
    t.start()
    t.join()
    return result[0]


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread scheduling policy is Linux's")
def test_fifo_priority_raises_the_device_thread_only(client: socket.socket) -> None:
    """A real box has a CPU of its own: with ``fifo_priority`` the device thread, and only it, runs at
    SCHED_FIFO; without it no thread does; where it is not permitted the box still streams."""
    before = _fifo_threads()
    with SimulatedHexBox(rate_hz=1000.0, counts=(1, 2, 3, 4, 5, 6)) as box:
        client.sendto(pack_request(CMD_START_REALTIME), box.address)
        assert len(records(client, 3)) == 3
        assert _fifo_threads() == before
    with SimulatedHexBox(rate_hz=1000.0, counts=(1, 2, 3, 4, 5, 6), fifo_priority=10) as box:
        client.sendto(pack_request(CMD_START_REALTIME), box.address)
        assert records(client, 3)[-1].counts[:3] == (1, 2, 3)
        raised = _fifo_threads() - before
        if _fifo_permitted():
            assert len(raised) == 1 and threading.get_native_id() not in raised
            assert thread_policy(raised.pop()) == (os.SCHED_FIFO, 10)
        else:
            assert not raised
