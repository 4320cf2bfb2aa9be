"""Starting child processes that leave the terminal's Ctrl-C to their parent, and whose start no
stop signal cuts short.

Ctrl-C in a terminal sends SIGINT to the whole process group: to a spawned child too, which may
still be importing its modules and would die there with a Python traceback. The parent owns the
shut-down (it asks its children to stop, then terminates them), so no child acts on SIGINT:

* :func:`sigint_blocked` blocks SIGINT in the calling thread just around a child's start (any
  thread may start one). The child inherits the blocked signal through its ``exec``: a Ctrl-C while
  it starts and imports stays pending. This process loses nothing: its other threads, or this one
  right after the block, take the signal.
* :func:`quietly` wraps the child's target (or a pool's initializer): it ignores SIGINT, which
  discards a pending one, then unblocks it, before the target runs. Handlers the target installs
  later (SIGTERM, SIGHUP...) work as usual.
* :func:`ensure_resource_tracker` keeps ``multiprocessing``'s resource tracker alive through a SIGHUP.

The parent's own stop handlers (:data:`STOP_SIGNALS`) typically raise, to end the command: one that
raised inside a ``spawn`` start, after the child was forked but before its start data were written
through the pipe, would close that pipe unwritten, and the child would die with a traceback
(``EOFError: Ran out of input``), unknown to the parent. :func:`stops_deferred` holds those handlers
back until the start is done; blocking the signals instead would leave the children blocking them
too (through the ``exec``), unkillable while they import.

:func:`starting_children` puts the block and the deferral together around any code that starts
children (``Process.start``, the ``pool.submit`` that spawns a worker); :func:`quiet_process` and
:func:`start_quiet` use it for one ``multiprocessing`` process.
"""

from __future__ import annotations

import contextlib
import functools
import signal
import threading
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Any

QUIET: frozenset[signal.Signals] = frozenset({signal.SIGINT})

STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
"""The signals that stop a lapwrench command: Ctrl-C, ``kill`` (or a service manager), a closed terminal."""

Handler = Callable[[int, FrameType | None], Any] | int
"""A signal's disposition as :func:`signal.signal` takes it: a function, ``SIG_DFL`` or ``SIG_IGN``."""


@contextlib.contextmanager
def sigint_blocked() -> Iterator[None]:
    """Processes started inside the block (from this thread) begin with SIGINT blocked; see the module."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, QUIET)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)  # a Ctrl-C that came meanwhile arrives now


class _Deferred:
    """The stand-in handler of :func:`stops_deferred`: notes the signals that came, each once, in order."""

    def __init__(self) -> None:
        self.came: dict[int, None] = {}  # an ordered set: a signal that comes twice is pending once

    def __call__(self, signum: int, _frame: FrameType | None) -> None:
        self.came.setdefault(signum)

    def redeliver(self) -> None:
        """Raise each noted signal again, in the order they came: every one reaches its handler, even
        when an earlier one's raises (that exception, chained, leaves here after the last)."""
        with contextlib.ExitStack() as later:
            for signum in reversed(self.came):  # the stack calls back last in, first out
                later.callback(signal.raise_signal, signum)


@contextlib.contextmanager
def stops_deferred() -> Iterator[None]:
    """Inside the block, a stop signal (:data:`STOP_SIGNALS`) is only noted; after it, the handlers
    are back and each noted signal is raised again, so that its handler runs (and may raise) once
    the block has finished: around a child's start, never in the middle of it (see the module).

    Only the Python-level handlers change, never the signal mask: a child started inside keeps its
    signals deliverable, and gets no stand-in (``exec`` resets every handled signal to its default,
    as it does the parent's own handlers; ``tests/test_spawn.py`` checks it). An ignored signal stays ignored
    (the child inherits ``SIG_IGN``), and a handler not set from Python is left alone. Outside the
    main thread nothing changes: handlers run in the main thread, and cannot cut a start in another
    one short. Keep the block to the starts: a signal waits for its end."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    deferred = _Deferred()
    previous: dict[signal.Signals, Handler] = {}
    try:
        for sig in STOP_SIGNALS:
            handler = signal.getsignal(sig)
            if handler is not None and handler != signal.SIG_IGN:
                previous[sig] = handler  # noted before the swap: restored whenever this is cut short
                signal.signal(sig, deferred)
        yield
    finally:
        with contextlib.ExitStack() as restore:  # every handler back, whatever one of them raises
            restore.callback(deferred.redeliver)  # called last
            for sig, handler in previous.items():
                restore.callback(signal.signal, sig, handler)


@contextlib.contextmanager
def starting_children() -> Iterator[None]:
    """Around code that starts child processes from this thread: they begin with SIGINT blocked
    (:func:`sigint_blocked`), and this process's stop handlers run only after every start in the
    block has finished (:func:`stops_deferred`)."""
    with stops_deferred(), sigint_blocked():
        yield


def ensure_resource_tracker() -> None:
    """Start ``multiprocessing``'s resource tracker now, if it is not running, with SIGHUP blocked.

    The tracker (which unlinks the shared memory and semaphores of processes that died) ignores
    SIGINT and SIGTERM, but not SIGHUP: a closed terminal would end it with the process group, and
    its relaunch then prints tracebacks about names it never saw. Call it before creating a
    queue, a lock or shared memory; :func:`start_quiet` calls it."""
    from multiprocessing import resource_tracker

    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGHUP})
    try:
        resource_tracker.ensure_running()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _call_quietly(target: Callable[..., Any], *args: Any) -> Any:
    for sig in QUIET:
        signal.signal(sig, signal.SIG_IGN)  # also drops a Ctrl-C that came while the child started
    signal.pthread_sigmask(signal.SIG_UNBLOCK, QUIET)
    return target(*args)


def quietly(target: Callable[..., Any]) -> Callable[..., Any]:
    """``target`` run with SIGINT ignored and no longer blocked: the child's side of
    :func:`sigint_blocked`. Picklable when ``target`` is; call it in the child's main thread."""
    return functools.partial(_call_quietly, target)


def quiet_process(ctx: Any, target: Callable[..., Any], args: tuple[Any, ...] = (), **kwargs: Any) -> Any:
    """``ctx.Process(target=target, args=args, **kwargs)``, its target run :func:`quietly`; start it
    with :func:`start_quiet`."""
    return ctx.Process(target=quietly(target), args=args, **kwargs)


def start_quiet(proc: Any) -> Any:
    """Start ``proc`` (from :func:`quiet_process`) inside :func:`starting_children` and return it. A
    stop signal during the start reaches this process's handler right after it: should that handler
    raise, the process has started all the same (``proc.pid`` is set) and is the caller's to stop."""
    ensure_resource_tracker()
    with starting_children():
        proc.start()
    return proc
