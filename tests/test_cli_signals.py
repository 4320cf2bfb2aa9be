"""The stop signals of every command (:mod:`lapwrench.cli_signals`): the line and exit code, the handler
that raises once, and a signal that comes inside an import waiting for its end."""

from __future__ import annotations

import ctypes
import ctypes.util
import importlib
import inspect
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lapwrench.cli_signals import (
    StopOnce,
    Stopped,
    handle_stop_signals,
    raisable,
    restore,
    signal_of,
    stop_line,
    stop_once,
)
from lapwrench.spawn import STOP_SIGNALS

OWN = (str(Path(__file__).parent) + os.sep,)  # this file's code counts as lapwrench's own (raisable)


class NotHandledError(Exception):
    """What a stop signal raises in a test when no lapwrench handler took it."""


def not_handled(signum: int, _frame: object) -> None:
    raise NotHandledError(signal.Signals(signum).name)


@pytest.fixture
def kept_handlers() -> Iterator[None]:
    """Every stop signal handled by the test (whatever the runner left: pytest-xdist's worker, a shell's
    SIG_IGN), then the handlers as they were."""
    before = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    for sig in STOP_SIGNALS:
        signal.signal(sig, not_handled)
    yield
    for sig, handler in before.items():
        signal.signal(sig, handler)


def test_the_line_names_the_command_and_the_signal() -> None:
    assert stop_line("demo", signal.SIGINT) == "lapwrench demo: interrupted"
    assert stop_line("log-report", signal.SIGTERM) == "lapwrench log-report: stopped by SIGTERM"
    assert stop_line(None, signal.SIGHUP) == "lapwrench: stopped by SIGHUP"


def test_the_first_signal_raises_stopped_and_the_later_ones_are_ignored(kept_handlers: None) -> None:
    with stop_once(OWN) as stop:
        with pytest.raises(Stopped) as info:
            signal.raise_signal(signal.SIGTERM)
        assert info.value.signum == signal.SIGTERM and isinstance(info.value, KeyboardInterrupt)
        signal.raise_signal(signal.SIGINT)  # the command is closing what it opened: ignored
        signal.raise_signal(signal.SIGHUP)
    assert stop.signum == signal.SIGTERM
    with pytest.raises(NotHandledError):  # the handlers of before the block are back
        signal.raise_signal(signal.SIGTERM)


def test_the_signal_behind_a_plain_keyboard_interrupt_is_the_one_the_handler_took(kept_handlers: None) -> None:
    """Ray's waits turn the Stopped our handler raises into a new, plain KeyboardInterrupt: a SIGTERM of a
    sweep was reported as Ctrl-C (exit 130). The handler in place still knows which signal it was."""
    assert signal_of(KeyboardInterrupt()) == signal.SIGINT  # Python's own Ctrl-C
    with stop_once(OWN):
        with pytest.raises(Stopped):
            signal.raise_signal(signal.SIGTERM)
        assert signal_of(KeyboardInterrupt()) == signal.SIGTERM
    assert signal_of(Stopped(signal.SIGHUP)) == signal.SIGHUP


def test_a_signal_the_shell_left_ignored_stays_ignored_and_restore_puts_back_the_others(kept_handlers: None) -> None:
    signal.signal(signal.SIGHUP, signal.SIG_IGN)  # as nohup leaves it
    before_int = signal.getsignal(signal.SIGINT)
    previous = handle_stop_signals(StopOnce())
    assert signal.getsignal(signal.SIGHUP) == signal.SIG_IGN and signal.SIGHUP not in previous
    assert isinstance(signal.getsignal(signal.SIGINT), StopOnce)
    restore(previous)
    assert signal.getsignal(signal.SIGINT) is before_int


def test_only_lapwrench_s_own_code_is_raisable() -> None:
    """Not a library's Python code (it may be a callback from C code: numba's dispatch dropped the exception,
    or a Pinocchio call crashed after it), nor code outside lapwrench unless named as its own."""
    here = inspect.currentframe()
    assert here is not None and here.f_back is not None
    assert raisable(here, OWN, here.f_back) and not raisable(here, base=here.f_back)  # this file: not lapwrench's
    assert not raisable(here, OWN, here.f_back.f_back)  # pytest's Python code below it: a library's
    seen: list[bool] = []
    np.apply_along_axis(lambda row: seen.append(raisable(inspect.currentframe(), OWN, here)) or row, 0, np.zeros(1))
    assert seen == [False]  # numpy's Python code between the callback and the test


def test_ray_s_waits_are_raisable_other_libraries_are_not() -> None:
    """A sweep's main thread waits in ``ray.wait``, which checks the signals once a second and passes a
    KeyboardInterrupt on: waiting for the command to leave Ray delayed every stop of a sweep by WAIT_S."""
    here = inspect.currentframe()

    def frame_of(filename: str) -> Any:
        namespace: dict[str, Any] = {"inspect": inspect}
        exec(compile("def frame():\n    return inspect.currentframe()\n", filename, "exec"), namespace)
        return namespace["frame"]()

    site = f"{os.sep}venv{os.sep}lib{os.sep}site-packages{os.sep}"
    assert raisable(frame_of(f"{site}ray{os.sep}_private{os.sep}worker.py"), OWN, here)
    assert not raisable(frame_of(f"{site}numba{os.sep}core{os.sep}compiler.py"), OWN, here)
    assert not raisable(frame_of(f"{site}rayon{os.sep}x.py"), OWN, here)


def test_a_signal_inside_an_import_waits_for_its_end(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, kept_handlers: None
) -> None:
    """A module cut halfway stays half-made (pandas: the next import of it fails with a traceback): the
    signal that comes while one is imported is taken once the import is over, and the module is whole."""
    name = "lapwrench_test_slow_module"
    (tmp_path / f"{name}.py").write_text(textwrap.dedent("""
        import os, signal, time
        os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C while this module is imported
        for _ in range(20):  # more module code after it: bytecode, where a handler runs
            time.sleep(0.005)
        WHOLE = True
    """))
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(Stopped), stop_once(OWN):
        module = importlib.import_module(name)
        assert module.WHOLE
        time.sleep(30)  # the command goes on: the signal, sent again, stops it here
    assert sys.modules[name].WHOLE
    del sys.modules[name]


class SignalledWhenCollected:
    """An object whose destructor gets a SIGTERM: Python cannot raise there (as in a callback from C code,
    numba's compiler's), and prints the exception with its traceback, then drops it."""

    def __del__(self) -> None:
        signal.raise_signal(signal.SIGTERM)


def test_a_stop_python_could_not_raise_is_not_printed_but_sent_again(
    capsys: pytest.CaptureFixture[str], kept_handlers: None
) -> None:
    hook = sys.unraisablehook
    with pytest.raises(Stopped) as info, stop_once(OWN) as stop:
        SignalledWhenCollected()  # collected at once: its destructor is signalled
        time.sleep(10)  # the command goes on: the signal, sent again, stops it here
    assert info.value.signum == signal.SIGTERM and stop.signum == signal.SIGTERM
    assert "Traceback" not in capsys.readouterr().err and sys.unraisablehook is hook


def test_a_stop_in_a_callback_from_c_code_is_sent_again_not_printed(
    capsys: pytest.CaptureFixture[str], kept_handlers: None
) -> None:
    """The CI failure of 3828080: llvmlite calls back into Python (its object cache) while numba compiles a
    fresh clone's kernels; a SIGTERM raised there was printed ('Exception ignored on calling ctypes callback
    function' and a traceback) and dropped, and ``virtual`` ran on to exit 0. Here C's qsort calls back into
    this file's code (lapwrench's own for the test), which gets the signal."""
    libc = ctypes.CDLL(ctypes.util.find_library("c"))
    compare_t = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.POINTER(ctypes.c_int), ctypes.POINTER(ctypes.c_int))

    def compare(a: Any, b: Any) -> int:
        signal.raise_signal(signal.SIGTERM)  # taken here, in a callback from C code
        return int(a[0] - b[0])

    values = (ctypes.c_int * 2)(2, 1)
    with pytest.raises(Stopped) as info, stop_once(OWN):
        libc.qsort(values, 2, ctypes.sizeof(ctypes.c_int), compare_t(compare))
        time.sleep(30)  # the command goes on: the signal, sent again, stops it here
    assert info.value.signum == signal.SIGTERM
    assert capsys.readouterr().err == ""


CONSOLE_SCRIPT = str(Path(sys.executable).with_name("lapwrench"))  # what pip installed: `lapwrench ...`


@pytest.mark.slow
@pytest.mark.parametrize(("entry", "sig"), [([sys.executable, "-m", "lapwrench"], signal.SIGINT),
                                            ([sys.executable, "-m", "lapwrench"], signal.SIGTERM),
                                            ([CONSOLE_SCRIPT], signal.SIGINT)])
def test_a_signal_at_any_moment_of_a_command_is_one_line_and_128_plus_its_number(
    entry: list[str], sig: signal.Signals, tmp_path: Path
) -> None:
    """``lapwrench virtual``, signalled from lapwrench.cli's imports on (Python's import-time report says when
    they are under way; before them Python itself starts, out of lapwrench's reach) to the run itself: one
    line, 130 or 143, never a traceback."""
    env = {**os.environ, "PYTHONPROFILEIMPORTTIME": "1", "MUJOCO_GL": "egl"}
    expected = {stop_line(None, sig), stop_line("virtual", sig)}
    for delay in (0.0, 0.05, 0.2, 0.5, 1.0, 2.0, 3.0, 5.0):
        proc = subprocess.Popen(
            [*entry, "virtual", "--duration", "30", "--quiet", "--out", str(tmp_path)],
            stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, env=env,
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),  # as a terminal's foreground job
        )
        assert proc.stderr is not None
        for line in proc.stderr:  # argparse: lapwrench.cli's first import after its handlers went in
            if line.split("|")[-1].strip() == "argparse":
                break
        time.sleep(delay)
        proc.send_signal(sig)
        err = proc.stderr.read()
        proc.wait(timeout=120)
        lines = [x for x in err.splitlines() if not x.startswith("import time:")]
        assert "Traceback" not in err and proc.returncode == 128 + sig, (delay, err[-3000:])
        assert len(lines) == 1 and lines[0] in expected, (delay, lines)
