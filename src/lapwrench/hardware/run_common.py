"""What the two run paths of ``lapwrench run`` share: the stop signals, the summary line and the
exit code of an error.

Signals (:class:`StopSignals`)
------------------------------
SIGINT (Ctrl-C), SIGTERM (``kill``, a service manager) and SIGHUP (the terminal closed) are
handled from the start of the command to the last line it prints:

* **before the loop starts** (devices, the real-time process, the log being set up; nothing has
  moved): the run is abandoned (:class:`RunInterrupted`), everything opened is closed, one line
  ``lapwrench run: stopped by SIGTERM before the loop started; the robot was not moved`` and exit
  code 128 + the signal number (130, 143, 129);
* **once the loop runs**: the first signal requests the clean stop (:class:`StopRequest`): the
  supervisor's jerk-limited stop to rest within the limits, then the summary (with
  ``"stop_reason": "SIGTERM"``) and the finalized log. The exit code is that of the run: **0**
  when it ended at rest without an alarm (a requested stop is how a run without ``--duration``
  ends), 1 after an alarm, 3 for a robot error;
* **any further signal** while the stop is under way, and while the log is being finalized, is
  ignored with one line ``lapwrench run: stopping, please wait (SIGINT ignored)``: it must not
  cut the stop to rest short, nor leave a truncated log (the same while an abandoned start-up or
  a failed run closes what it opened: :meth:`StopSignals.closing`). The stop is still bounded:
  the loop's own stop deadline (``stop_timeout`` of robot time), and in the default process path
  the parent's wall-clock bound on the child (:class:`~lapwrench.hardware.rt.RtProcess`
  ``stop_wait``) and its heartbeat watch.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from types import FrameType
from typing import Any

from lapwrench.hardware.devices import CliError
from lapwrench.spawn import STOP_SIGNALS


def _error_exit(exc: Exception) -> int:
    """Report the error that ended a run (``lapwrench run: ...``) and return its exit code: 2 for an
    argument or device problem, 3 for a robot error (including the real-time process dying or hanging)."""
    from lapwrench.hardware.rt.spec import RtProcessError

    if isinstance(exc, CliError):
        print(f"lapwrench run: {exc}", file=sys.stderr)
        return 2
    if isinstance(exc, RtProcessError) and getattr(exc, "kind", "") == "device":
        print(f"lapwrench run: device not ready: {exc}", file=sys.stderr)
        return 2
    print(f"lapwrench run: robot error: {exc}", file=sys.stderr)
    return 3


class RunInterrupted(BaseException):
    """A stop signal before the loop started: the run is abandoned (nothing has moved).

    A ``BaseException``, like ``KeyboardInterrupt``, so that no ``except Exception`` on the way
    swallows it; the ``finally`` blocks close what was opened.
    """

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def exit_code(self) -> int:
        return 128 + self.signum

    def report(self) -> int:
        """The one line for the user; returns the exit code."""
        _write_stderr(
            f"lapwrench run: stopped by {signal.Signals(self.signum).name} before the loop started;"
            " the robot was not moved\n"
        )
        return self.exit_code


class StopRequest:
    """The stop request the loop polls (``is_set()``, as a ``threading.Event``), with its reason:
    the name of the signal that asked for it and when (``time.monotonic()``)."""

    def __init__(self) -> None:
        self._event = threading.Event()
        self.reason: str | None = None
        self.at: float | None = None

    def is_set(self) -> bool:
        return self._event.is_set()

    def set(self, reason: str = "stop requested") -> None:
        if not self._event.is_set():
            self.reason, self.at = reason, time.monotonic()
            self._event.set()

    def wait(self, timeout: float | None = None) -> bool:
        return self._event.wait(timeout)


class StopSignals:
    """SIGINT, SIGTERM and SIGHUP for the whole of ``lapwrench run`` (see the module docstring).

    Used as a context manager around everything the command does; :meth:`arm` marks the point
    from which a signal requests the clean stop (``stop``) instead of abandoning the start-up.
    Installed only in the main thread (Python's rule); elsewhere it does nothing.
    """

    def __init__(self, command: str = "run") -> None:
        self.command = command
        self.stop = StopRequest()
        self.received: list[str] = []
        self._armed = False
        self._quiet = False  # stopping, abandoned or closing: further signals are only noted
        self._previous: dict[signal.Signals, Any] | None = None

    def __enter__(self) -> StopSignals:
        if threading.current_thread() is threading.main_thread():
            self._previous = {sig: signal.signal(sig, self._handle) for sig in STOP_SIGNALS}
        return self

    def __exit__(self, *exc: object) -> None:
        if self._previous is not None:
            for sig, handler in self._previous.items():
                signal.signal(sig, handler)
            self._previous = None

    def arm(self) -> StopRequest:
        """From now on a signal requests the clean stop to rest; returns the request to poll."""
        self._armed = True
        return self.stop

    def closing(self) -> None:
        """From now on (closing devices, finalizing the log) a signal is noted and ignored."""
        self._quiet = True

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        name = signal.Signals(signum).name
        self.received.append(name)
        if self.stop.is_set() or self._quiet:
            _write_stderr(f"lapwrench {self.command}: stopping, please wait ({name} ignored)\n")
            return
        if not self._armed:
            self._quiet = True
            raise RunInterrupted(signum)
        self.stop.set(name)
        _write_stderr(f"lapwrench {self.command}: {name}: stopping to rest\n")


def run_signalled(body: Callable[[argparse.Namespace, Any, StopSignals], int], args: argparse.Namespace,
                  cfg: Any) -> int:
    """Run one path of ``lapwrench run`` (``body(args, cfg, signals)``) with the stop signals handled
    from start to end (module docstring); a signal before the loop starts ends it with 128 + n."""
    with StopSignals() as signals:
        try:
            return body(args, cfg, signals)
        except RunInterrupted as exc:
            return exc.report()


def _write_stderr(text: str) -> None:
    """Straight to file descriptor 2: safe in a signal handler (no buffered writer to re-enter),
    and silent when the terminal is gone (SIGHUP)."""
    with contextlib.suppress(OSError):
        os.write(2, text.encode())


def stop_reason(stop: StopRequest, stats: Any, child_signal: str | None = None) -> str:
    """Why the run ended: the signal that asked for the stop, ``alarm`` or ``duration``."""
    if stop.reason is not None:
        return stop.reason
    if child_signal is not None:
        return f"{child_signal} (to the real-time process)"
    return "alarm" if stats.alarm else "duration"


def print_summary(summary: dict[str, Any]) -> None:
    """The summary line on stdout. If stdout is gone (a terminal hung up: SIGHUP), it is pointed at
    /dev/null so that neither this nor the interpreter's final flush ends the command in a traceback
    or another exit code."""
    try:
        print(json.dumps(summary), flush=True)
    except OSError:
        with contextlib.suppress(OSError, ValueError):
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
            os.close(devnull)


def open_logger(args: argparse.Namespace, cfg: Any, meta: dict[str, Any]) -> Any:
    """The run's :class:`~lapwrench.hardware.log.RunLogger` for ``--log`` and/or ``--foxglove`` (None
    without either): with the robot model, so the file and the live view get the transforms, the
    scope pose and the wrench arrows. A live server that cannot start is a :class:`CliError`."""
    if not args.log and not getattr(args, "foxglove", None):
        return None
    from lapwrench.hardware.log import RunLogger
    from lapwrench.hardware.log.live import LiveError
    from lapwrench.robot.description import ScopeGeometry
    from lapwrench.robot.model import RobotModel

    model = RobotModel(cfg.robot.kind, ScopeGeometry.from_config(cfg.scope))
    try:
        logger = RunLogger(args.log, meta, model=model, live=getattr(args, "foxglove", None))
    except LiveError as exc:
        raise CliError(f"--foxglove {exc}") from exc
    if logger.live is not None:
        host, port = logger.live.address
        print(f"lapwrench run: live telemetry for Foxglove on ws://{host}:{port}", file=sys.stderr)
    return logger
