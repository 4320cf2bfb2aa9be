"""lapwrench.drivers.base: a streaming source's life cycle (open in the caller's thread, read in its
own, stop promptly and once) and what its reader thread counts instead of dying."""

from __future__ import annotations

import threading
import time
from collections import deque

import pytest

from lapwrench.drivers.base import (
    DeviceError,
    DeviceOpenError,
    EndOfStream,
    PacketError,
    StreamingSource,
)


class Script(StreamingSource[int]):
    """A device that plays ``steps``: an int is published, an exception is raised, then the end
    (``[...]``: samples until stopped)."""

    def __init__(self, steps: list[object], *, present: bool = True) -> None:
        super().__init__("script", io_backoff_s=0.001)
        self.steps = deque(steps)
        self.present = present
        self.opened_in: str | None = None
        self.closed = 0

    def _open(self) -> None:
        if not self.present:
            raise DeviceOpenError("/dev/script0", "no such device")
        self.opened_in = threading.current_thread().name

    def _read_once(self) -> None:
        if self.steps == deque([...]):  # endless: a sample a millisecond
            time.sleep(0.001)
            self._publish(0, time.monotonic())
            return
        if not self.steps:
            raise EndOfStream
        step = self.steps.popleft()
        if isinstance(step, BaseException):
            raise step
        self._publish(step, time.monotonic())  # type: ignore[arg-type]

    def _close(self) -> None:
        self.closed += 1


def wait_finished(src: Script) -> None:
    deadline = time.monotonic() + 5.0
    while src.running and time.monotonic() < deadline:
        time.sleep(0.001)


def test_a_missing_device_fails_in_the_callers_thread_before_any_thread_runs() -> None:
    src = Script([], present=False)
    with pytest.raises(DeviceOpenError, match=r"^/dev/script0: no such device$") as err:
        src.start()
    assert err.value.device == "/dev/script0" and isinstance(err.value, DeviceError)
    assert not src.running and src.closed == 0


def test_bad_packets_and_io_errors_are_counted_and_the_thread_goes_on() -> None:
    src = Script([1, PacketError("short record"), 2, OSError("cable pulled"), 3]).start()
    assert src.opened_in == threading.current_thread().name
    wait_finished(src)
    status = src.status()
    assert (status.samples, status.malformed, status.io_errors, status.finished) == (3, 1, 1, True)
    assert status.last_error == "I/O error: OSError: cable pulled"
    assert src.latest() is not None and src.latest().value == 3  # type: ignore[union-attr]
    assert [msg for _, msg in src.errors] == ["malformed: short record", "I/O error: OSError: cable pulled"]
    src.stop()


def test_stop_is_idempotent_and_closes_the_device_once() -> None:
    src = Script([...])
    with src:
        assert src.running
    assert not src.running and src.stopping and src.closed == 1
    src.stop()
    assert src.closed == 1


def test_a_running_source_cannot_be_started_twice() -> None:
    src = Script([...]).start()
    try:
        with pytest.raises(RuntimeError, match="script: already started"):
            src.start()
    finally:
        src.stop()


def test_a_fresh_sample_is_one_younger_than_the_age_asked() -> None:
    src = Script([7]).start()
    wait_finished(src)
    assert src.fresh(10.0) and not src.fresh(0.0, now=time.monotonic() + 1.0)
    src.stop()
