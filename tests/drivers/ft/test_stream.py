"""The F/T UDP stream: record checks, counters, staleness, clean stop, clear errors, polled draining."""

from __future__ import annotations

import logging
import socket
import threading
import time
from collections.abc import Iterator

import numpy as np
import pytest
from helpers import FT_RATE_HZ, kernel_arrival_stamps, open_fds, wait_until

from lapwrench.drivers.base import DeviceTimeoutError
from lapwrench.drivers.ft import (
    CMD_START_REALTIME,
    CMD_STOP,
    AtiNetFTSensor,
    OnRobotHexSensor,
    pack_record,
    pack_request,
    unpack_request,
)
from lapwrench.drivers.simulated_hex import SimulatedHexBox


def test_malformed_packets_are_counted_and_thread_survives(device: SimulatedHexBox) -> None:
    device.counts = np.array([10000, 0, 0, 0, 0, 0])
    with OnRobotHexSensor(*device.address) as s:
        device.inject([b"\x01\x02\x03", b"\x00" * 40, pack_request(CMD_START_REALTIME), b""])
        assert wait_until(lambda: s.status().malformed >= 4)
        st = s.status()
        assert st.running
        assert "malformed" in (st.last_error or "")
        before = s.latest().seq
        assert s.buffer.wait_newer(before + 5, timeout=2.0) is not None  # data keeps flowing
        assert s.status().malformed == 4


def test_status_word_rejects_records(device: SimulatedHexBox) -> None:
    with OnRobotHexSensor(*device.address) as s:
        device.status = 0x80000001
        assert wait_until(lambda: s.status().malformed >= 3)
        assert s.status().drops == 0  # rejected records are not lost records
        assert s.last_status == 0x80000001
        seq = s.latest().seq
        time.sleep(0.05)
        assert s.latest().seq == seq  # nothing published while the device reports an error
        device.status = 0
        assert s.buffer.wait_newer(seq, timeout=2.0) is not None


def test_rate_monitor_drops_and_out_of_order(device: SimulatedHexBox) -> None:
    with OnRobotHexSensor(*device.address, expected_rate_hz=FT_RATE_HZ) as s:
        time.sleep(0.3)
        st = s.status()
        assert st.rate_hz == pytest.approx(FT_RATE_HZ, rel=0.35)
        assert st.drops == 0
        device.skip(5)
        device.duplicate(2)
        assert wait_until(lambda: s.status().drops >= 5 and s.status().out_of_order >= 2)
        st = s.status()
        assert st.drops == 5
        assert st.out_of_order == 2


def test_staleness_when_peer_goes_silent(device: SimulatedHexBox) -> None:
    with OnRobotHexSensor(*device.address) as s:
        assert s.fresh(0.1)
        assert s.buffer.get_fresh(0.1) is not None
        device.pause()
        time.sleep(0.02)
        age0 = s.buffer.age()
        time.sleep(0.15)
        assert s.buffer.age() > age0 + 0.1  # age grows
        assert not s.fresh(0.1)
        assert s.buffer.get_fresh(0.1) is None  # the control loop switches this wrench off
        assert wait_until(lambda: s.rate.rate() == 0.0 or s.status().rate_hz < FT_RATE_HZ / 2, timeout=2.0)
        device.resume()
        assert wait_until(lambda: s.fresh(0.05))


def test_stop_cleans_up_thread_and_socket(device: SimulatedHexBox) -> None:
    baseline = threading.active_count()
    fds = open_fds()
    s = OnRobotHexSensor(*device.address).start()
    (thread,) = (t for t in threading.enumerate() if t.name == f"lapwrench-{s.name}")
    assert thread.is_alive() and s.running
    assert threading.active_count() == baseline + 1
    assert len(open_fds()) == len(fds) + 1  # its socket
    t0 = time.monotonic()
    s.stop()
    assert time.monotonic() - t0 < 1.0
    assert not thread.is_alive()
    assert not s.running
    assert open_fds() == fds  # the socket is closed
    with pytest.raises(RuntimeError, match="not started"):
        s.send_command(CMD_STOP)
    assert threading.active_count() == baseline
    assert wait_until(lambda: (CMD_STOP, 0) in device.commands)
    assert wait_until(lambda: not device.streaming)
    s.stop()  # idempotent
    # restartable: the device restarts its sequence at 1, which must not look out-of-order
    seq_before = s.latest().seq
    with s:
        assert s.latest().seq > seq_before
        assert s.buffer.wait_newer(seq_before + 20, timeout=2.0) is not None
        assert s.status().out_of_order == 0


def test_no_device_gives_clear_timeout_error() -> None:
    # a bound but silent UDP port: requests vanish, nothing answers
    silent = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    silent.bind(("127.0.0.1", 0))
    port = silent.getsockname()[1]
    baseline = threading.active_count()
    try:
        s = OnRobotHexSensor("127.0.0.1", port, start_timeout=0.3)
        t0 = time.monotonic()
        with pytest.raises(DeviceTimeoutError, match=rf"OnRobot HEX sensor at udp://127.0.0.1:{port}"):
            s.start()
        assert time.monotonic() - t0 < 2.0
        assert not s.running
        assert threading.active_count() == baseline
    finally:
        silent.close()


def test_closed_port_gives_clear_error() -> None:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()  # nothing listens: the kernel answers with ICMP port unreachable
    s = AtiNetFTSensor("127.0.0.1", port, start_timeout=0.3)
    with pytest.raises(DeviceTimeoutError, match="ATI Net F/T") as info:
        s.start()
    assert str(port) in str(info.value)
    assert not s.running


def test_errors_before_the_first_record_are_one_error_not_a_warning_each(caplog: pytest.LogCaptureFixture) -> None:
    """A box that never answers: start() fails with the counts and the last error, and nothing is
    logged per retry (it printed five warning lines before the one-line error)."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    port = sock.getsockname()[1]
    sock.close()
    s = OnRobotHexSensor("127.0.0.1", port, start_timeout=0.3)
    with caplog.at_level(logging.WARNING, logger="lapwrench.drivers"), pytest.raises(DeviceTimeoutError) as info:
        s.start()
    assert "io_errors=" in str(info.value) and "last error" in str(info.value)
    assert not [r for r in caplog.records if r.name.startswith("lapwrench.drivers")]


def test_errors_after_streaming_are_logged(device: SimulatedHexBox, caplog: pytest.LogCaptureFixture) -> None:
    with caplog.at_level(logging.WARNING, logger="lapwrench.drivers"), OnRobotHexSensor(*device.address) as s:
        assert s.buffer.wait_newer(0, timeout=2.0) is not None
        device.inject([b"\x01\x02\x03"])
        assert wait_until(lambda: s.status().malformed >= 1)
    assert any("malformed" in r.getMessage() for r in caplog.records)


def test_control_loop_reads_never_block_while_streaming(device: SimulatedHexBox) -> None:
    """A 1 kHz loop's per-cycle read (get_fresh) costs microseconds, even with the reader busy."""
    with OnRobotHexSensor(*device.address) as s:
        worst = 0.0
        t_start = time.perf_counter()
        for _ in range(2000):
            t0 = time.perf_counter()
            sample = s.buffer.get_fresh(0.5)
            worst = max(worst, time.perf_counter() - t0)
            assert sample is not None
        total = time.perf_counter() - t_start
    assert total < 0.5
    assert worst < 0.05  # generous bound for a loaded 2-core CI box (typically ~1 us)


# --------------------------------------------------------------------------- polled mode (no thread)
class RawPeer:
    """A loopback 'device' socket the test drives datagram by datagram."""

    def __init__(self) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", 0))
        self.sock.settimeout(2.0)
        self.port = self.sock.getsockname()[1]
        self.client: tuple[str, int] | None = None

    def answer_start(self) -> threading.Thread:
        """Reply to the first start request with one record (seq 1), from a thread."""

        def run() -> None:
            while True:
                data, addr = self.sock.recvfrom(64)
                if unpack_request(data)[1] == CMD_START_REALTIME:
                    self.client = addr
                    self.sock.sendto(pack_record(1, 1, 0, [0] * 6), addr)
                    return

        t = threading.Thread(target=run, daemon=True)
        t.start()
        return t

    def send(self, data: bytes) -> None:
        assert self.client is not None
        self.sock.sendto(data, self.client)

    def close(self) -> None:
        self.sock.close()


@pytest.fixture
def peer() -> Iterator[RawPeer]:
    p = RawPeer()
    try:
        yield p
    finally:
        p.close()


def settle(s: OnRobotHexSensor, n: int) -> int:
    """Drain until ``n`` datagrams were read (loopback delivery is not instantaneous)."""
    got = 0
    deadline = time.monotonic() + 2.0
    while got < n and time.monotonic() < deadline:
        got += s.drain()
        time.sleep(0.001)
    return got


def test_drain_reads_everything_pending_and_publishes_only_the_newest(peer: RawPeer) -> None:
    peer.answer_start().join(0)
    s = OnRobotHexSensor("127.0.0.1", peer.port).start_polled()
    try:
        assert s.polled and not s.running  # no reader thread
        seq0 = s.latest().seq
        assert s.drain() == 0 and s.latest().seq == seq0  # nothing pending: returns at once (non-blocking)
        for i in range(2, 7):
            peer.send(pack_record(i, i, 0, [10000 * i, 0, 0, 0, 0, 0]))
        assert settle(s, 5) == 5
        sample = s.latest()
        assert sample.seq == seq0 + 1  # five records read, one published
        np.testing.assert_allclose(sample.value.force, [6.0, 0.0, 0.0])  # the newest
        assert s.status().drops == 0 and s.status().samples == seq0 + 1
    finally:
        s.stop()
    assert not s.polled


def test_a_backlog_drained_late_is_stamped_when_it_arrived_not_when_it_was_read(peer: RawPeer) -> None:
    """After a stall, what waited in the socket is as old as it is: a sample drained 150 ms after it came is
    not fresh (before, it was stamped with the drain's time; after a stall longer than the socket holds,
    the kernel keeps the oldest datagrams, so that made data hundreds of ms old look new)."""
    peer.answer_start().join(0)
    s = OnRobotHexSensor("127.0.0.1", peer.port).start_polled()
    try:
        with kernel_arrival_stamps():  # the kernel stamps arrivals from a moment after the first socket asks
            for i in range(2, 12):
                peer.send(pack_record(i, i, 0, [10000 * i, 0, 0, 0, 0, 0]))
            sent = time.monotonic()
            time.sleep(0.15)
            assert s.drain() == 10
        sample = s.latest()
        np.testing.assert_allclose(sample.value.force, [11.0, 0.0, 0.0])
        assert sample.timestamp <= sent + 0.01  # arrived about when sent, not when drained
        assert not s.fresh(max_age=0.02)
    finally:
        s.stop()


def test_drain_reads_at_most_its_budget_and_leaves_the_rest_queued(peer: RawPeer) -> None:
    """A flood cannot hold the caller: ``max_datagrams`` bounds one drain; the next drain reads on."""
    peer.answer_start().join(0)
    s = OnRobotHexSensor("127.0.0.1", peer.port).start_polled()
    try:
        for i in range(2, 42):
            peer.send(b"\x00" * 20 if i % 2 else pack_record(i, i, 0, [10000, 0, 0, 0, 0, 0]))  # half junk
        time.sleep(0.05)
        assert s.drain(max_datagrams=16) == 16
        assert s.drain(max_datagrams=16) == 16
        assert s.drain(max_datagrams=16) == 8
        assert s.status().malformed == 20
    finally:
        s.stop()


def test_drain_skips_malformed_and_status_error_records_and_keeps_the_newest_valid(peer: RawPeer) -> None:
    peer.answer_start().join(0)
    s = OnRobotHexSensor("127.0.0.1", peer.port).start_polled()
    try:
        peer.send(pack_record(2, 2, 0, [20000, 0, 0, 0, 0, 0]))
        peer.send(b"\x00" * 20)  # malformed
        peer.send(pack_record(3, 3, 0x40, [90000, 0, 0, 0, 0, 0]))  # device error word
        peer.send(pack_record(2, 2, 0, [70000, 0, 0, 0, 0, 0]))  # out of order (duplicate seq)
        assert settle(s, 4) == 4
        np.testing.assert_allclose(s.latest().value.force, [2.0, 0.0, 0.0])
        st = s.status()
        assert st.malformed == 2 and st.out_of_order == 1 and s.last_status == 0x40
    finally:
        s.stop()


def test_a_rejected_record_far_ahead_does_not_stall_the_stream(peer: RawPeer) -> None:
    """Issue 11: one record with sequence + 900 (a status error, or corrupt) used to make the driver
    drop the next 900 good records; now it costs nothing (status error) or one packet (good status)."""
    peer.answer_start().join(0)
    s = OnRobotHexSensor("127.0.0.1", peer.port).start_polled()
    try:
        peer.send(pack_record(2, 2, 0, [10000, 0, 0, 0, 0, 0]))
        peer.send(pack_record(902, 902, 0x40, [0] * 6))  # status error, far ahead
        peer.send(pack_record(950, 950, 0, [0] * 6))  # clean status but far ahead and alone: unconfirmed
        peer.send(pack_record(3, 3, 0, [30000, 0, 0, 0, 0, 0]))  # the good stream goes on
        assert settle(s, 4) == 4
        np.testing.assert_allclose(s.latest().value.force, [3.0, 0.0, 0.0])
        assert s.status().drops == 0
    finally:
        s.stop()


def test_a_wrench_beyond_any_sensor_range_is_a_corrupt_record(peer: RawPeer) -> None:
    peer.answer_start().join(0)
    s = OnRobotHexSensor("127.0.0.1", peer.port).start_polled()
    try:
        peer.send(pack_record(2, 2, 0, [2_000_000_000, 0, 0, 0, 0, 0]))  # 200 kN at the HEX's scale
        peer.send(pack_record(3, 3, 0, [50000, 0, 0, 0, 0, 0]))
        assert settle(s, 2) == 2
        np.testing.assert_allclose(s.latest().value.force, [5.0, 0.0, 0.0])
        assert s.status().malformed >= 1
    finally:
        s.stop()
