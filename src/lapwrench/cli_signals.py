"""The stop signals of every ``lapwrench`` command.

SIGINT (Ctrl-C), SIGTERM (``kill``, a service manager) and SIGHUP (a closed terminal) end a command with
one line on stderr (``lapwrench <command>: interrupted``, or ``... stopped by SIGTERM``) and exit code
128 + the signal's number (130, 143, 129), never a traceback:

* while the program starts (its imports, the parser's, the arguments' parsing) nothing is open or
  written: :func:`exit_at_once` ends it at once. :mod:`lapwrench.cli` installs it before its other
  imports, which is why this module imports only the standard library's basics;
* while a command runs (:func:`stop_once`), :class:`StopOnce` raises :class:`Stopped` (a
  ``KeyboardInterrupt``) for the first signal, so that the command's own handlers and ``finally`` blocks
  close what it opened, and ignores the later ones. It is raised only in lapwrench's own code
  (:func:`raisable`): a signal that comes inside an import waits for its end (a module cut halfway cannot
  be imported again: the clean-up's next import of it would fail with a traceback), and one that comes
  in a library's code (numba's dispatch, matplotlib, a callback from C code) waits until the library
  returns (raised there, it was dropped, or left memory corrupt: a crash). It waits at most
  :data:`WAIT_S`: a fresh clone's first run compiles numba's kernels for longer than that (3 s into
  ``virtual`` with an empty cache, the signal met only numba's compiler for 5 s), and then it is raised
  where it is, as Python's own Ctrl-C would be;
* whatever became of the exception (swallowed on its way, still waiting when the command returned, or
  the signal came after it), :func:`lapwrench.cli.main` ends with the signal's line and code when
  :class:`StopOnce` noted one: never the exit code of a command that ran to its end.

Python runs a handler in the main thread, between two bytecodes: a signal that comes in compiled code (a
numba kernel, a MuJoCo or Pinocchio call) or while another thread runs is taken when the main thread is
next in Python code. A signal the shell left ignored (``nohup``, a background job of a script) stays ignored. ``run``,
``demo`` and ``ui`` install a stop of their own over these while they run.
"""

from __future__ import annotations

import contextlib
import inspect
import os
import signal
import sys
import sysconfig
import threading
import time
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Any

from lapwrench.spawn import STOP_SIGNALS

WAIT_S = 5.0
"""A signal that comes where it cannot be raised safely (:func:`raisable`) waits at most this long for the
command to be back in code where it can (then it raises where it is, as Python's own Ctrl-C would)."""

PACKAGE_DIR = os.path.dirname(os.path.abspath(__file__)) + os.sep
STDLIB_DIR = sysconfig.get_paths()["stdlib"] + os.sep
RETRY_S = 0.02  # how often a waiting signal is sent again

Handler = Callable[[int, FrameType | None], object] | int | None
"""A signal's disposition as :func:`signal.getsignal` gives it."""


def stop_line(command: str | None, signum: int) -> str:
    """The one line for a stop signal: ``lapwrench demo: interrupted`` (SIGINT), ``... stopped by SIGTERM``."""
    how = "interrupted" if signum == signal.SIGINT else f"stopped by {signal.Signals(signum).name}"
    return f"lapwrench{f' {command}' if command else ''}: {how}"


class Stopped(KeyboardInterrupt):
    """A stop signal while a command runs (:class:`StopOnce`); the exit code is 128 + ``signum``."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


def exit_at_once(signum: int, _frame: FrameType | None) -> None:
    """The handler while the program starts: its line and exit code at once, whatever runs (a module's
    import, a destructor: no exception that could escape as a traceback)."""
    with contextlib.suppress(OSError):  # stderr closed
        os.write(2, f"{stop_line(None, signum)}\n".encode())
    os._exit(128 + signum)


def exit_quietly(signum: int, _frame: FrameType | None) -> None:
    """The handler once a stop signal's line is out (the command ended by it, Python exiting): the exit code
    at once, no second line."""
    os._exit(128 + signum)


INTERRUPTIBLE = ("ray",)
"""Installed packages whose Python code is made for Ctrl-C: raised there, the stop comes out as a
KeyboardInterrupt. Ray's ``ray.wait`` checks the signals once a second and is where a sweep's or a tune's
main thread spends its time: waiting for the command to leave it delayed every stop of a sweep by
:data:`WAIT_S` (a SIGTERM halfway ended it 9.9 s later, after the next job had finished)."""


def installed_package(filename: str) -> str | None:
    """The top-level package of an installed library's file (under site- or dist-packages), else None."""
    for folder in (f"{os.sep}site-packages{os.sep}", f"{os.sep}dist-packages{os.sep}"):
        if folder in filename:
            return filename.split(folder, 1)[1].split(os.sep, 1)[0]
    return None


def raisable(frame: FrameType | None, own: tuple[str, ...] = (), base: FrameType | None = None) -> bool:
    """Whether an exception may be raised in ``frame``: every frame of its stack above ``base`` (the frame
    that runs the command; None: the whole stack) is lapwrench's, the standard library's (not the packages
    installed beside it, but :data:`INTERRUPTIBLE`'s) or under one of the folders ``own``, and none is an
    import's. A library's Python
    code may run as a callback from C code that does not pass the exception on, or that a call cut halfway
    leaves corrupt: raised in numba's dispatch, a SIGTERM was dropped (the command ran on and ended with 0)
    or the next Pinocchio call crashed (SIGSEGV); a module cut halfway cannot be imported again."""
    ours = (PACKAGE_DIR, *own)
    while frame is not None and frame is not base:
        name = frame.f_code.co_filename
        package = installed_package(name)
        if name.startswith("<frozen importlib._bootstrap") or not (
            name.startswith(("<", *ours)) or (name.startswith(STDLIB_DIR) and package is None)
            or package in INTERRUPTIBLE
        ):
            return False
        frame = frame.f_back
    return True


class StopOnce:
    """The handler while a command runs: the first signal raises :class:`Stopped` (``signum`` keeps it),
    the later ones are ignored. Where it cannot be raised safely (:func:`raisable`; ``own``: folders of
    code that counts as lapwrench's) the signal is sent again every :data:`RETRY_S` until the command is
    back in its own code, for at most :data:`WAIT_S`; one that Python swallowed all the same (raised in a
    destructor: :meth:`unraisable`) is sent again too. :func:`stop_once` installs it."""

    def __init__(self, own: tuple[str, ...] = (), base: FrameType | None = None) -> None:
        self.own = own
        self.base = base  # the frame that runs the command: the stack below it is not looked at
        self.signum: int | None = None
        self.raised = False  # raised already, or the command is over: a signal is only noted
        self.over = False  # the command is over (:meth:`cancel`)
        self._until = 0.0
        self._retry: threading.Timer | None = None

    def __call__(self, signum: int, frame: FrameType | None) -> None:
        if self.signum is None:
            self.signum, self._until = signum, time.monotonic() + WAIT_S
        if self.raised:  # raised already, or the command is over (:meth:`cancel`): only noted
            return
        if not raisable(frame, self.own, self.base) and time.monotonic() < self._until:
            self._send_again()
            return
        self.raised = True
        raise Stopped(self.signum)

    def unraisable(self, exc: BaseException | None) -> bool:
        """Whether ``exc``, an exception Python could not raise (``sys.unraisablehook``: it came in a
        callback from C code, numba's compiler's say, or in a destructor, and would be printed with its
        traceback, then dropped), is this handler's :class:`Stopped`: then the signal is sent again."""
        if not isinstance(exc, Stopped) or self.signum is None:
            return False
        if not self.over:  # after the command nothing is raised: its caller reports the signal noted
            self.raised = False
            self._send_again()
        return True

    def cancel(self) -> None:
        """The command is over: no signal sent again or raised any more; a first one is still noted
        (``signum``: the caller ends with its line and code, not with the finished command's)."""
        self.raised = self.over = True
        if self._retry is not None:
            self._retry.cancel()

    def _send_again(self) -> None:
        if self._retry is None or not self._retry.is_alive():
            self._retry = threading.Timer(RETRY_S, os.kill, (os.getpid(), self.signum))
            self._retry.daemon = True
            self._retry.start()


@contextlib.contextmanager
def stop_once(own: tuple[str, ...] = ()) -> Iterator[StopOnce]:
    """Within the block the stop signals raise once (:class:`StopOnce`, with ``own``; the caller's frame is
    its ``base``), and a :class:`Stopped` that Python could not raise is sent again rather than printed; the
    handlers and ``sys.unraisablehook`` are back after it."""
    here = inspect.currentframe()  # this generator's, resumed by contextlib's __enter__, called by the caller
    caller = here.f_back.f_back if here is not None and here.f_back is not None else None
    stop = StopOnce(own, caller)
    previous = handle_stop_signals(stop)
    hook = sys.unraisablehook

    def unraisable(info: Any) -> None:
        if not stop.unraisable(info.exc_value):
            hook(info)

    sys.unraisablehook = unraisable
    try:
        yield stop
    finally:
        stop.cancel()
        sys.unraisablehook = hook
        restore(previous)


def signal_of(exc: BaseException) -> int:
    """The number of the stop signal behind a ``KeyboardInterrupt``: a :class:`Stopped`'s own; for a plain
    one, the signal the :class:`StopOnce` in place took (Ray's waits turn the exception the handler raised
    into a new KeyboardInterrupt, without it); else SIGINT (Python's own Ctrl-C)."""
    signum = getattr(exc, "signum", None)
    if isinstance(signum, int):
        return signum
    for sig in STOP_SIGNALS:
        handler = signal.getsignal(sig)
        if isinstance(handler, StopOnce) and handler.signum is not None:
            return handler.signum
    return signal.SIGINT


def handle_stop_signals(handler: Handler) -> dict[signal.Signals, Handler]:
    """Install ``handler`` for every stop signal the shell did not leave ignored; returns the handlers it
    replaced (for :func:`restore`). Outside the main thread (where Python allows no handler) nothing."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    previous: dict[signal.Signals, Handler] = {}
    for sig in STOP_SIGNALS:
        old = signal.getsignal(sig)
        if old != signal.SIG_IGN:
            previous[sig] = old
            signal.signal(sig, handler)
    return previous


def restore(previous: dict[signal.Signals, Handler]) -> None:
    """Put back the handlers :func:`handle_stop_signals` replaced (one not set from Python: the default)."""
    for sig, handler in previous.items():
        signal.signal(sig, handler if handler is not None else signal.SIG_DFL)
