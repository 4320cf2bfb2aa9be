"""Starting child processes that leave the terminal's Ctrl-C to their parent.

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

:func:`quiet_process` and :func:`start_quiet` put the two together for one ``multiprocessing`` process.
"""

from __future__ import annotations

import contextlib
import functools
import signal
from collections.abc import Callable, Iterator
from typing import Any

QUIET: frozenset[signal.Signals] = frozenset({signal.SIGINT})


@contextlib.contextmanager
def sigint_blocked() -> Iterator[None]:
    """Processes started inside the block (from this thread) begin with SIGINT blocked; see the module."""
    old = signal.pthread_sigmask(signal.SIG_BLOCK, QUIET)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)  # a Ctrl-C that came meanwhile arrives now


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
    """Start ``proc`` (from :func:`quiet_process`) with SIGINT blocked (:func:`sigint_blocked`) and
    return it. A Ctrl-C during the start reaches this process's handler right after it: should that
    handler raise, the process has started all the same (``proc.pid`` is set) and is the caller's to stop."""
    ensure_resource_tracker()
    with sigint_blocked():
        proc.start()
    return proc
