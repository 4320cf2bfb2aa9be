"""lapwrench.drivers.arrival: the kernel's arrival stamp of a datagram, on the reader's clock."""

from __future__ import annotations

import socket
import sys
import time
from collections.abc import Iterator

import pytest
from helpers import kernel_arrival_stamps

from lapwrench.drivers import arrival


@pytest.fixture
def pair() -> Iterator[tuple[socket.socket, socket.socket]]:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    tx.connect(rx.getsockname())
    try:
        yield rx, tx
    finally:
        rx.close()
        tx.close()


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="SO_TIMESTAMPNS is Linux's")
def test_a_datagram_read_late_carries_the_time_it_arrived(pair: tuple[socket.socket, socket.socket]) -> None:
    rx, tx = pair
    assert arrival.enable(rx)
    with kernel_arrival_stamps():  # the kernel stamps arrivals from a moment after the first socket asks
        tx.send(b"record")
        time.sleep(0.1)  # read 100 ms (or more, on a busy machine) after it came
        data, stamp = arrival.recv_stamped(rx, 2048)
        now, wall = time.monotonic(), time.time()
    assert data == b"record" and stamp is not None
    assert 0.1 <= now - arrival.on_clock(stamp, now, wall) < 5.0


def test_without_the_option_there_is_no_stamp_and_the_read_time_stands(
    pair: tuple[socket.socket, socket.socket],
) -> None:
    rx, tx = pair
    tx.send(b"record")
    data, stamp = arrival.recv_stamped(rx, 2048)
    assert data == b"record" and stamp is None
    assert arrival.on_clock(None, 12.5, 1.7e9) == 12.5


def test_the_arrival_is_never_later_than_now() -> None:
    assert arrival.on_clock(1.7e9 - 0.25, 100.0, 1.7e9) == pytest.approx(99.75)
    assert arrival.on_clock(1.7e9 + 3.0, 100.0, 1.7e9) == 100.0  # the wall clock stepped back since
