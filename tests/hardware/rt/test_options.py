"""lapwrench.hardware.rt.options: the real-time process's scheduling, and what it says when a setting
is not permitted (the run goes on at normal priority, with one line naming the fix)."""

from __future__ import annotations

import ctypes
import errno
import os
import resource
import subprocess
import sys

import pytest

from lapwrench.hardware.rt import options
from lapwrench.hardware.rt.options import MCL_CURRENT, MCL_FUTURE, RtOptions, apply_realtime, lock_memory


def test_the_defaults_ask_for_fifo_80_locked_memory_and_a_frozen_collector() -> None:
    opts = RtOptions()
    assert (opts.fifo_priority, opts.cpus, opts.lock_memory, opts.gc_freeze, opts.warn) == (80, None, True, True, True)


@pytest.mark.parametrize("priority", [0, 100, -5])
def test_a_fifo_priority_outside_1_to_99_is_refused(priority: int) -> None:
    with pytest.raises(ValueError, match=f"1..99, got {priority}"):
        RtOptions(fifo_priority=priority)


def test_nothing_asked_is_nothing_applied() -> None:
    assert apply_realtime(RtOptions(fifo_priority=None, cpus=None)) == []


class FakeLibc:
    """libc's mlockall, answering ``result`` (and ``err`` in errno)."""

    def __init__(self, result: int, err: int = 0) -> None:
        self.result, self.err = result, err
        self.calls: list[int] = []

    def mlockall(self, flags: int) -> int:
        self.calls.append(flags)
        ctypes.set_errno(self.err)
        return self.result


def test_locking_memory_asks_for_the_pages_mapped_now_and_later(monkeypatch: pytest.MonkeyPatch) -> None:
    libc = FakeLibc(0)
    monkeypatch.setattr(ctypes, "CDLL", lambda *a, **k: libc)
    monkeypatch.setattr(options, "has_capability", lambda cap: True)
    assert lock_memory() is None
    assert libc.calls == [MCL_CURRENT | MCL_FUTURE]


def test_under_a_finite_memlock_limit_nothing_is_locked_and_the_fix_is_named(monkeypatch: pytest.MonkeyPatch) -> None:
    """Locked, every later page would count against the limit, and past it an allocation would fail mid-motion."""
    libc = FakeLibc(0)
    monkeypatch.setattr(ctypes, "CDLL", lambda *a, **k: libc)
    monkeypatch.setattr(options, "has_capability", lambda cap: False)
    monkeypatch.setattr(resource, "getrlimit", lambda what: (8 << 20, 8 << 20))
    problem = lock_memory()
    assert problem is not None and problem.startswith("memory not locked: RLIMIT_MEMLOCK is 8192 kB, not unlimited")
    assert "memlock unlimited" in problem and libc.calls == []


def test_a_refused_mlockall_is_reported_not_raised(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(ctypes, "CDLL", lambda *a, **k: FakeLibc(-1, errno.ENOMEM))
    monkeypatch.setattr(options, "has_capability", lambda cap: True)
    assert lock_memory() == f"memory not locked: mlockall failed ({os.strerror(errno.ENOMEM)}); the loop's pages" \
        " may fault in during a cycle"


def test_a_process_that_locks_its_memory_has_it_all_resident() -> None:
    """In a process of its own (the lock stays for the life of a process): locked, or a message saying why not."""
    code = (
        "from lapwrench.hardware.rt.options import lock_memory; import numpy as np; p = lock_memory();"
        "a = np.empty(1 << 20);"  # mapped after the lock: resident (and locked) from its mapping on
        "print(p); print([l.split()[1] for l in open('/proc/self/status') if l.startswith('VmLck')][0])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    problem, locked_kb = out.stdout.splitlines()
    if problem == "None":
        assert int(locked_kb) > 8 << 10  # the interpreter, numpy and the 8 MB array
    else:
        assert problem.startswith("memory not locked") and int(locked_kb) == 0


def test_pinning_to_cpus_the_process_may_use_is_applied() -> None:
    before = os.sched_getaffinity(0)
    try:
        assert apply_realtime(RtOptions(fifo_priority=None, cpus=(min(before),))) == []
        assert os.sched_getaffinity(0) == {min(before)}
    finally:
        os.sched_setaffinity(0, before)


def test_a_cpu_that_does_not_exist_is_reported_not_raised() -> None:
    before = os.sched_getaffinity(0)
    problems = apply_realtime(RtOptions(fifo_priority=None, cpus=(4095,)))
    assert len(problems) == 1 and problems[0].startswith("CPU affinity [4095] not applied")
    assert os.sched_getaffinity(0) == before


def test_a_fifo_priority_not_permitted_says_how_to_grant_it(monkeypatch: pytest.MonkeyPatch) -> None:
    def refuse(pid: int, policy: int, param: object) -> None:
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(os, "sched_setscheduler", refuse)
    (problem,) = apply_realtime(RtOptions(fifo_priority=50))
    assert problem.startswith("SCHED_FIFO priority 50 not permitted (PermissionError")
    assert "ulimit -r 99" in problem and "PREEMPT_RT" in problem
