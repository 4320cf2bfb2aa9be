"""What the two run paths of ``lapwrench run`` share: Ctrl-C handling and the exit code of an error."""

from __future__ import annotations

import signal
import sys
import threading
from typing import Any

from lapwrench.hardware.devices import CliError


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


def _install_sigint(stop: threading.Event) -> Any:
    """Ctrl-C and SIGTERM request a clean stop to rest instead of killing the loop mid-command."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum: int, frame: Any) -> None:
        stop.set()

    return {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}


def _restore_sigint(previous: Any) -> None:
    if previous is not None:
        for sig, h in previous.items():
            signal.signal(sig, h)
