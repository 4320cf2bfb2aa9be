"""Children started through lapwrench.spawn leave Ctrl-C to their parent, and a stop signal waits for
their starts to finish."""

from __future__ import annotations

import multiprocessing as mp
import multiprocessing.util
import os
import signal
import threading
import time
from collections.abc import Iterator
from types import FrameType
from typing import Any

import pytest

from lapwrench.spawn import (
    ensure_resource_tracker,
    quiet_process,
    sigint_blocked,
    start_quiet,
    starting_children,
    stops_deferred,
)


def _report_sigint(conn: Any) -> None:
    """In the child: its SIGINT disposition and whether SIGINT is blocked, then a SIGINT to itself."""
    conn.send((signal.getsignal(signal.SIGINT) is signal.SIG_IGN, signal.SIGINT in signal.pthread_sigmask(
        signal.SIG_BLOCK, set())))
    os.kill(os.getpid(), signal.SIGINT)  # ignored: the child goes on
    conn.send("alive")


def test_a_child_started_quietly_ignores_sigint_and_keeps_it_unblocked() -> None:
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe()
    proc = start_quiet(quiet_process(ctx, _report_sigint, (child,), daemon=True))
    child.close()
    assert parent.poll(60.0)
    assert parent.recv() == (True, False)
    assert parent.recv() == "alive"
    proc.join(30.0)
    assert proc.exitcode == 0


def test_the_parent_keeps_its_handler_and_gets_a_sigint_sent_while_blocked() -> None:
    got: list[int] = []
    old = signal.signal(signal.SIGINT, lambda signum, _frame: got.append(signum))
    try:
        with sigint_blocked():
            # to this thread (os.kill would let another thread of the process, e.g. pytest-xdist's, take it)
            signal.pthread_kill(threading.get_ident(), signal.SIGINT)
            assert got == []  # pending while a child starts
        for _ in range(100):  # delivered at the next bytecode boundary
            if got:
                break
            time.sleep(0.01)
        assert got == [signal.SIGINT]
        assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, set())
    finally:
        signal.signal(signal.SIGINT, old)


class _StoppedError(Exception):
    """What the stop handler of these tests raises, as the commands' handlers do."""


@pytest.fixture
def stop_handler() -> Iterator[list[str]]:
    """A SIGTERM handler that notes its call in the list it yields, then raises :class:`_StoppedError`."""
    calls: list[str] = []

    def stop(signum: int, _frame: FrameType | None) -> None:
        calls.append(f"handler {signal.Signals(signum).name}")
        raise _StoppedError

    old = signal.signal(signal.SIGTERM, stop)
    try:
        yield calls
    finally:
        signal.signal(signal.SIGTERM, old)


def _sigterm_to_this_thread() -> None:
    # to this thread (os.kill would let another thread of the process, e.g. pytest-xdist's, take it);
    # the handler, if it runs now, runs before this returns
    signal.pthread_kill(threading.get_ident(), signal.SIGTERM)


def test_a_stop_signal_while_children_start_reaches_its_handler_once_the_starts_are_done(
    stop_handler: list[str],
) -> None:
    handler = signal.getsignal(signal.SIGTERM)
    with pytest.raises(_StoppedError), starting_children():
        stop_handler.append("start begins")
        _sigterm_to_this_thread()  # mid-start: from a `kill`, say
        _sigterm_to_this_thread()  # a second one is pending once, as with a blocked signal
        stop_handler.append("start ends")
    assert stop_handler == ["start begins", "start ends", "handler SIGTERM"]
    assert signal.getsignal(signal.SIGTERM) is handler  # the handler is back


def test_every_stop_signal_that_came_is_delivered_even_when_a_handler_raises(stop_handler: list[str]) -> None:
    got: list[int] = []
    old = signal.signal(signal.SIGHUP, lambda signum, _frame: got.append(signum))
    try:
        with pytest.raises(_StoppedError), stops_deferred():
            _sigterm_to_this_thread()
            signal.pthread_kill(threading.get_ident(), signal.SIGHUP)
            assert stop_handler == [] and got == []
        assert stop_handler == ["handler SIGTERM"]
        assert got == [signal.SIGHUP]
    finally:
        signal.signal(signal.SIGHUP, old)


def _say_alive(conn: Any) -> None:
    conn.send("alive")


def test_a_stop_signal_before_a_child_has_its_start_data_leaves_it_started(
    stop_handler: list[str], monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str],
) -> None:
    """The signal comes once the child is forked, before the parent writes its start data into the pipe:
    the start finishes, the child runs, and then the handler raises (once). A handler raising there
    used to close the pipe unwritten: the child died with ``EOFError: Ran out of input``."""
    ensure_resource_tracker()  # its start is not the one under test
    spawn = multiprocessing.util.spawnv_passfds
    forked: list[int] = []

    def spawn_then_stop(path: str, args: list[str], passfds: Any) -> int:
        pid = spawn(path, args, passfds)
        forked.append(pid)
        stop_handler.append("child forked")
        _sigterm_to_this_thread()
        return pid

    monkeypatch.setattr(multiprocessing.util, "spawnv_passfds", spawn_then_stop)
    ctx = mp.get_context("spawn")
    parent, child = ctx.Pipe()
    proc = quiet_process(ctx, _say_alive, (child,), daemon=True)
    with pytest.raises(_StoppedError):
        start_quiet(proc)
    monkeypatch.undo()
    assert stop_handler == ["child forked", "handler SIGTERM"]
    assert forked == [proc.pid]  # started all the same
    child.close()
    assert parent.poll(60.0)
    assert parent.recv() == "alive"
    proc.join(30.0)
    assert proc.exitcode == 0
    assert "Traceback" not in capfd.readouterr().err


def _report_handlers(conn: Any) -> None:
    conn.send((signal.getsignal(signal.SIGTERM), signal.getsignal(signal.SIGHUP)))


def test_a_child_starts_with_the_default_stop_handlers_and_keeps_an_ignored_signal_ignored(
    stop_handler: list[str],
) -> None:
    """Neither the parent's Python handlers nor the stand-in of the deferral reach a spawned child
    (``exec`` resets them); a signal the parent ignores (``nohup``) stays ignored in the child."""
    old = signal.signal(signal.SIGHUP, signal.SIG_IGN)
    try:
        ctx = mp.get_context("spawn")
        parent, child = ctx.Pipe()
        proc = start_quiet(quiet_process(ctx, _report_handlers, (child,), daemon=True))
        child.close()
        assert parent.poll(60.0)
        assert parent.recv() == (signal.SIG_DFL, signal.SIG_IGN)
        proc.join(30.0)
        assert proc.exitcode == 0
    finally:
        signal.signal(signal.SIGHUP, old)
    assert stop_handler == []
