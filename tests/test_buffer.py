"""LatestValue and RateMonitor: semantics, non-blocking reads, counters."""

from __future__ import annotations

import math
import threading
import time

import numpy as np
import pytest

from lapwrench.buffer import LatestValue, RateMonitor, Sample


def test_empty_buffer_is_stale() -> None:
    buf: LatestValue[int] = LatestValue("x")
    assert buf.get() is None
    assert buf.age() == math.inf
    assert not buf.fresh(1e9)


def test_put_get_seq_age_fresh() -> None:
    buf: LatestValue[str] = LatestValue("x")
    s1 = buf.put("a", timestamp=10.0)
    s2 = buf.put("b", timestamp=10.5)
    assert isinstance(s1, Sample)
    assert (s1.seq, s2.seq) == (1, 2)
    latest = buf.get()
    assert latest is s2
    assert latest.value == "b"
    assert buf.age(now=11.0) == pytest.approx(0.5)
    assert buf.fresh(0.6, now=11.0)
    assert not buf.fresh(0.4, now=11.0)
    assert latest.age(now=12.0) == pytest.approx(1.5)
    assert buf.get_fresh(0.6, now=11.0) is s2
    assert buf.get_fresh(0.4, now=11.0) is None


def test_default_timestamp_is_monotonic_now() -> None:
    buf: LatestValue[int] = LatestValue()
    before = time.monotonic()
    s = buf.put(1)
    assert before <= s.timestamp <= time.monotonic()


def test_get_does_not_block_while_writer_holds_lock() -> None:
    lock = threading.Lock()
    buf: LatestValue[int] = LatestValue(lock=lock)
    buf.put(7)
    seen: list[int] = []

    def read() -> None:
        for _ in range(1000):
            sample = buf.get()
            assert sample is not None and buf.fresh(1.0)
            seen.append(sample.value)

    with lock:  # a writer stuck inside put()
        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        reader.join(timeout=10.0)  # a deadlock detector, not a speed limit
        assert not reader.is_alive(), "get() waited for the writers' lock"
    assert seen == [7] * 1000


def test_concurrent_writers_and_readers_keep_seq_monotonic() -> None:
    buf: LatestValue[tuple[int, int]] = LatestValue()
    n_per_writer = 2000
    stop = threading.Event()
    errors: list[str] = []

    def writer(k: int) -> None:
        for i in range(n_per_writer):
            buf.put((k, i))

    def reader() -> None:
        last = 0
        while not stop.is_set():
            s = buf.get()
            if s is not None:
                if s.seq < last:
                    errors.append(f"seq went back {last} -> {s.seq}")
                last = s.seq

    readers = [threading.Thread(target=reader) for _ in range(2)]
    writers = [threading.Thread(target=writer, args=(k,)) for k in range(3)]
    for t in readers + writers:
        t.start()
    for t in writers:
        t.join(10)
    stop.set()
    for t in readers:
        t.join(10)
    assert not errors
    assert buf.get().seq == 3 * n_per_writer


def test_wait_newer_returns_and_times_out() -> None:
    buf: LatestValue[int] = LatestValue()
    assert buf.wait_newer(0, timeout=0.01) is None
    timer = threading.Timer(0.02, buf.put, args=(5,))
    timer.start()
    try:
        s = buf.wait_newer(0, timeout=2.0)
    finally:
        timer.cancel()
        timer.join()
    assert s is not None and s.value == 5
    assert buf.wait_newer(s.seq, timeout=0.01) is None


def test_a_waiter_that_timed_out_leaves_the_others_woken_by_put() -> None:
    """put notifies only while someone waits (a count kept under the lock): a waiter that gave up must not
    leave the count wrong for one still waiting, nor the count stay up once all have returned. A waiter
    not notified would sleep its whole 60 s timeout; woken, it returns at once (10 s of margin)."""
    buf: LatestValue[int] = LatestValue()

    def waiter(after: int, out: list[object]) -> threading.Thread:
        t = threading.Thread(target=lambda: out.append(buf.wait_newer(after, timeout=60.0)), daemon=True)
        t.start()
        return t

    got: list[object] = []
    patient = waiter(0, got)
    assert buf.wait_newer(0, timeout=0.01) is None  # this one gives up while the other still waits
    buf.put(7)
    patient.join(10.0)
    assert not patient.is_alive(), "the waiter was not woken by put"
    assert getattr(got[0], "value", None) == 7
    for _ in range(3):  # no one waits now: puts go on without notifying
        buf.put(8)
    late: list[object] = []
    seq = buf.get().seq  # type: ignore[union-attr]
    t = waiter(seq, late)
    while t.is_alive() and not late:
        buf.put(9)  # until the new waiter has seen one: it may start waiting after any of these
        t.join(0.01)
    t.join(10.0)
    assert not t.is_alive(), "a later waiter was not woken by put"
    assert getattr(late[0], "value", None) == 9


def test_rate_monitor_estimates_rate_and_decays() -> None:
    rm = RateMonitor(window_s=1.0)
    for i in range(201):
        rm.tick(now=100.0 + i * 0.005)  # 200 Hz for 1 s
    assert rm.rate(now=101.0) == pytest.approx(200.0, rel=0.02)
    assert rm.rate(now=101.5) < 150.0  # half the window empty
    assert rm.rate(now=102.1) == 0.0  # everything left the window
    assert rm.stats(now=102.1).count == 201


def test_rate_monitor_late_counter() -> None:
    rm = RateMonitor(window_s=1.0, expected_rate_hz=100.0, late_factor=3.0)
    t = 0.0
    for _ in range(10):
        t += 0.01
        rm.tick(now=t)
    rm.tick(now=t + 0.05)  # 5 periods: late
    rm.tick(now=t + 0.06)
    assert rm.stats(now=t + 0.06).late == 1


def test_rate_monitor_sequence_accounting() -> None:
    rm = RateMonitor()
    assert rm.check_seq(10)
    assert rm.check_seq(11)
    assert rm.check_seq(15)  # 12, 13, 14 lost
    assert not rm.check_seq(15)  # duplicate
    assert not rm.check_seq(14)  # late/reordered
    assert not rm.check_seq(1)  # 14 back is below restart_gap: out of order
    st = rm.stats()
    assert st.drops == 3
    assert st.out_of_order == 3


def test_rate_monitor_wraparound_and_restart() -> None:
    rm = RateMonitor(restart_gap=100)
    assert rm.check_seq(0xFFFFFFFF)
    assert rm.check_seq(0)  # wrap: +1
    assert rm.stats().drops == 0
    rm2 = RateMonitor(restart_gap=100)
    assert rm2.check_seq(50_000)
    assert rm2.check_seq(50_001)  # two in order: the stream is anchored
    assert not rm2.check_seq(1)  # device restarted its counter? not until the next packet confirms it
    assert rm2.check_seq(2)  # confirmed: one resync, no drops
    assert not rm2.check_seq(2)
    st = rm2.stats()
    assert st.resyncs == 1 and st.drops == 0 and st.out_of_order == 2


def test_a_near_sequence_jump_is_taken_back_when_the_stream_goes_on_from_before_it() -> None:
    """Found by the fuzz suite: one packet numbered last + 90 made the next 89 good ones out-of-order."""
    rm = RateMonitor()
    for s in range(10, 15):
        assert rm.check_seq(s)
    assert rm.check_seq(14 + 90)  # provisionally: maybe 89 packets were lost
    assert all(rm.check_seq(s) for s in range(15, 60))  # no: the stream goes on from before it
    st = rm.stats()
    assert st.drops == 0 and st.out_of_order == 0
    assert rm.check_seq(62) and rm.check_seq(63) and not rm.check_seq(61)  # a real loss (confirmed), a late one
    st = rm.stats()
    assert st.drops == 2 and st.out_of_order == 1


def test_a_bad_first_sequence_number_anchors_nothing() -> None:
    """Found by the fuzz suite: a first packet numbered 500 ahead made the next 500 good ones out-of-order."""
    rm = RateMonitor()
    assert rm.check_seq(500)  # the first number: nothing to compare it with
    assert all(rm.check_seq(s) for s in range(0, 50))  # the next one does not follow it: it anchors nothing
    st = rm.stats()
    assert st.drops == 0 and st.out_of_order == 0


def test_one_far_sequence_jump_costs_one_packet_and_no_drop_count() -> None:
    """A corrupt packet 900 ahead must not make the monitor discard the next 900 good ones (issue 11)."""
    rm = RateMonitor()
    for s in range(100, 110):
        assert rm.check_seq(s)
    assert not rm.check_seq(110 + 900)  # the outlier: discarded, not committed
    assert all(rm.check_seq(s) for s in range(110, 200))  # the good stream goes on
    st = rm.stats()
    assert st.drops == 0 and st.resyncs == 0 and st.out_of_order == 1


def test_random_sequence_numbers_do_not_inflate_the_drop_count() -> None:
    rm = RateMonitor()
    rng = np.random.default_rng(0)
    rm.check_seq(5)
    for s in rng.integers(0, 2**32, 1000):
        rm.check_seq(int(s))
    assert rm.stats().drops < 1000 * 100  # at most resync_gap per accepted packet, never ~1e11


def test_rate_monitor_validates_arguments() -> None:
    with pytest.raises(ValueError):
        RateMonitor(window_s=0)
    with pytest.raises(ValueError):
        RateMonitor(expected_rate_hz=-1)
