"""Children started through lapwrench.spawn leave Ctrl-C to their parent."""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
import threading
import time
from typing import Any

from lapwrench.spawn import quiet_process, sigint_blocked, start_quiet


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
