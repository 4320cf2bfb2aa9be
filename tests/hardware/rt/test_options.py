"""lapwrench.hardware.rt.options: the real-time process's scheduling, and what it says when a setting
is not permitted (the run goes on at normal priority, with one line naming the fix)."""

from __future__ import annotations

import os

import pytest

from lapwrench.hardware.rt.options import RtOptions, apply_realtime


def test_the_defaults_ask_for_fifo_80_and_a_frozen_collector() -> None:
    opts = RtOptions()
    assert (opts.fifo_priority, opts.cpus, opts.gc_freeze, opts.warn) == (80, None, True, True)


@pytest.mark.parametrize("priority", [0, 100, -5])
def test_a_fifo_priority_outside_1_to_99_is_refused(priority: int) -> None:
    with pytest.raises(ValueError, match=f"1..99, got {priority}"):
        RtOptions(fifo_priority=priority)


def test_nothing_asked_is_nothing_applied() -> None:
    assert apply_realtime(RtOptions(fifo_priority=None, cpus=None)) == []


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
