"""lapwrench.hardware.run_common: the stop signals of ``lapwrench run`` in-process (the end-to-end
cases with a real run are tests/hardware/test_signals.py), the stop reason, the summary line and the
run's logger."""

from __future__ import annotations

import argparse
import json
import signal
import threading
from pathlib import Path

import pytest

from lapwrench.config import load
from lapwrench.hardware.run_common import (
    STOP_SIGNALS,
    RunInterrupted,
    StopRequest,
    StopSignals,
    open_logger,
    print_summary,
    run_signalled,
    stop_reason,
)
from lapwrench.loop_stats import LoopStats


def test_a_stop_request_keeps_its_first_reason() -> None:
    stop = StopRequest()
    assert not stop.is_set() and stop.reason is None and not stop.wait(0.0)
    stop.set("SIGTERM")
    stop.set("SIGINT")
    assert stop.is_set() and stop.reason == "SIGTERM" and stop.at is not None and stop.wait(0.0)


def test_a_signal_before_the_loop_abandons_the_start_up_with_128_plus_n(capfd: pytest.CaptureFixture[str]) -> None:
    def body(args: argparse.Namespace, cfg: object, signals: StopSignals) -> int:
        signal.raise_signal(signal.SIGHUP)  # devices still opening: nothing has moved
        return 0

    assert run_signalled(body, argparse.Namespace(), None) == 128 + signal.SIGHUP
    assert capfd.readouterr().err == (
        "lapwrench run: stopped by SIGHUP before the loop started; the robot was not moved\n"
    )


def test_once_armed_the_first_signal_asks_for_the_stop_and_the_next_are_ignored(
    capfd: pytest.CaptureFixture[str],
) -> None:
    before = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    with StopSignals() as signals:
        stop = signals.arm()
        signal.raise_signal(signal.SIGTERM)
        signal.raise_signal(signal.SIGINT)
        assert stop.is_set() and stop.reason == "SIGTERM" and signals.received == ["SIGTERM", "SIGINT"]
    assert {sig: signal.getsignal(sig) for sig in STOP_SIGNALS} == before  # handlers given back
    assert capfd.readouterr().err.splitlines() == [
        "lapwrench run: SIGTERM: stopping to rest", "lapwrench run: stopping, please wait (SIGINT ignored)",
    ]


def test_while_closing_a_signal_is_only_noted(capfd: pytest.CaptureFixture[str]) -> None:
    with StopSignals("demo") as signals:
        signals.closing()
        signal.raise_signal(signal.SIGHUP)  # no RunInterrupted: the log is being finalized
        assert not signals.stop.is_set() and signals.received == ["SIGHUP"]
    assert "lapwrench demo: stopping, please wait (SIGHUP ignored)" in capfd.readouterr().err


def test_off_the_main_thread_no_handler_is_installed() -> None:
    before = signal.getsignal(signal.SIGTERM)
    seen: list[object] = []

    def enter() -> None:
        with StopSignals():
            seen.append(signal.getsignal(signal.SIGTERM))

    t = threading.Thread(target=enter)
    t.start()
    t.join()
    assert seen == [before]


def test_run_interrupted_is_no_ordinary_exception() -> None:
    assert not issubclass(RunInterrupted, Exception) and RunInterrupted(signal.SIGINT).exit_code == 130


def test_the_stop_reason_names_the_signal_then_the_child_then_the_alarm() -> None:
    stop, stats = StopRequest(), LoopStats()
    assert stop_reason(stop, stats) == "duration"
    stats.alarm = "rcm_error: 12 mm"
    assert stop_reason(stop, stats) == "alarm"
    assert stop_reason(stop, stats, "SIGHUP") == "SIGHUP (to the real-time process)"
    stop.set("SIGINT")
    assert stop_reason(stop, stats, "SIGHUP") == "SIGINT"


def test_the_summary_is_one_json_line(capsys: pytest.CaptureFixture[str]) -> None:
    print_summary({"cycles": 3, "alarm": None})
    assert json.loads(capsys.readouterr().out) == {"cycles": 3, "alarm": None}


def test_the_logger_is_opened_for_a_log_file_only(tmp_path: Path) -> None:
    cfg = load()
    assert open_logger(argparse.Namespace(log=None, foxglove=None), cfg, {}) is None
    logger = open_logger(argparse.Namespace(log=str(tmp_path / "run.mcap"), foxglove=None), cfg, {"robot": "x"})
    try:
        assert logger is not None and logger.live is None and logger.path == tmp_path / "run.mcap"
    finally:
        logger.close()
    assert (tmp_path / "run.mcap").stat().st_size > 0
