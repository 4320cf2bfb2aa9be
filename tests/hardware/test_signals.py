"""Stop signals on ``lapwrench run`` (issue 11, item 9).

SIGINT, SIGTERM and SIGHUP on a running ``lapwrench run --dry-run`` (the MuJoCo-simulated robot,
both process paths) must stop the arm to rest within its limits, print the summary with the
reason, finalize the log (``log-report`` reads it whole), and exit 0; a second signal during the
stop is ignored with a "please wait" line. A run killed outright (SIGKILL) leaves a truncated log
that ``log-report`` still reads as far as it goes. Timings are never asserted.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import select
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.hardware.log import load_log, log_report_main
from lapwrench.hardware.run_common import RunInterrupted, StopSignals
from lapwrench.robot.limits import limit_usage
from lapwrench.robot.model import RobotModel
from lapwrench.safety.supervisor import SupervisorConfig

pytestmark = pytest.mark.slow  # each case runs `lapwrench run --dry-run` in a subprocess

# the real command line (lapwrench.cli.main), as the console script runs it
CLI = [sys.executable, "-c", "import sys; from lapwrench.cli import main; sys.exit(main(sys.argv[1:]))"]
READY = "lapwrench run: simulated"  # "... ready; devices: ..." (process path) or "... connected; ..." (in-process)


@dataclass
class Run:
    proc: subprocess.Popen[str]
    log: Path
    stderr: str = ""

    def read_stderr_until(self, text: str, timeout: float = 180.0) -> None:
        """Read stderr lines until one contains ``text`` (never blocking past the timeout)."""
        assert self.proc.stderr is not None
        deadline = time.monotonic() + timeout
        while text not in self.stderr and time.monotonic() < deadline and self.proc.poll() is None:
            if select.select([self.proc.stderr], [], [], 1.0)[0]:
                self.stderr += self.proc.stderr.readline()
        assert text in self.stderr, self.stderr

    def finish(self, timeout: float = 120.0) -> str:
        """Wait for the exit; returns stdout (stderr is appended to :attr:`stderr`)."""
        out, err = self.proc.communicate(timeout=timeout)
        self.stderr += err
        return out


def launch(tmp_path: Path, *extra: str) -> Run:
    """``lapwrench run --dry-run --log`` in a session of its own (so that everything it starts can be
    cleaned up by its process group), waiting until the loop runs."""
    log = tmp_path / "run.mcap"
    proc = subprocess.Popen(
        [*CLI, "run", "--dry-run", "--log", str(log), "--max-misses", "0", "--rt-priority", "0", *extra],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=dict(os.environ, MUJOCO_GL="egl"),
        text=True,
        start_new_session=True,
    )
    run = Run(proc, log)
    try:
        run.read_stderr_until(READY)
    except BaseException:
        cleanup(run)
        raise
    return run


def cleanup(run: Run) -> None:
    """Kill what is left of the run's process group (only after a failure, or after SIGKILL's orphans
    had their time to stop on their own)."""
    if run.proc.poll() is None:
        run.proc.kill()
    run.proc.wait()
    deadline = time.monotonic() + 30.0
    while time.monotonic() < deadline:
        try:
            os.killpg(run.proc.pid, 0)
        except ProcessLookupError:
            return
        time.sleep(0.2)
    with contextlib.suppress(ProcessLookupError):
        os.killpg(run.proc.pid, signal.SIGKILL)


def assert_stopped_at_rest_within_limits(cycles: list[dict[str, Any]]) -> None:
    """The commands of the whole run (from rest) stay within the arm's limits, it moved, and the
    last command is at rest."""
    cfg = load()
    q_cmd = np.array([c["q_cmd"] for c in cycles], dtype=float)
    dt = cfg.robot.dt
    usage = limit_usage(q_cmd, dt, RobotModel(cfg.robot.kind).limits)
    assert usage["position_excess"] == 0.0
    for k in ("velocity", "acceleration", "jerk"):
        assert usage[k] <= 1.0, usage
    speed = np.abs(np.diff(q_cmd, axis=0)) / dt
    assert speed.max() > 1e-3, "the arm never moved: the stop would prove nothing"
    # the last command: below the supervisor's rest velocity (it then holds that pose)
    assert speed[-1].max() < SupervisorConfig().rest_velocity, speed[-1]
    assert cycles[-1]["supervisor"] == "holding"


def report_of(log: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = log_report_main(argparse.Namespace(log=str(log), out=str(tmp_path / "report")))
    return code, capsys.readouterr().err


SECOND = {signal.SIGINT: signal.SIGTERM, signal.SIGTERM: signal.SIGHUP, signal.SIGHUP: signal.SIGINT}


@pytest.mark.parametrize(
    ("sig", "extra"),
    [
        (signal.SIGINT, ()),
        (signal.SIGTERM, ()),
        (signal.SIGHUP, ()),
        (signal.SIGTERM, ("--in-process",)),
    ],
    ids=["SIGINT", "SIGTERM", "SIGHUP", "SIGTERM-in-process"],
)
def test_a_stop_signal_stops_to_rest_prints_the_summary_and_finalizes_the_log(
    sig: signal.Signals, extra: tuple[str, ...], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = launch(tmp_path, *extra)
    try:
        time.sleep(2.5)  # into the scripted push: the arm is moving
        run.proc.send_signal(sig)
        run.read_stderr_until(f"{sig.name}: stopping to rest", timeout=60)
        run.proc.send_signal(SECOND[sig])  # during the stop: must not cut it short
        out = run.finish()
    finally:
        cleanup(run)
    # a requested stop that ends at rest is a clean end of the run: exit code 0
    assert run.proc.returncode == 0, run.stderr
    assert "Traceback" not in run.stderr
    assert f"stopping, please wait ({SECOND[sig].name} ignored)" in run.stderr
    summary = json.loads(out.strip().splitlines()[-1])
    assert summary["stop_reason"] == sig.name
    assert summary["stopped_at_rest"] is True and summary["alarm"] is None
    assert summary["process"] == ("in-process" if extra else "rt")
    log = load_log(run.log)  # strict: a complete file, or LogFileError
    assert log.truncated is None and log.stats is not None
    assert len(log.cycles) == summary["cycles"] and log.stats["dropped"] == 0
    stops = [e for e in log.events if e["kind"] == "stop_requested"]
    assert len(stops) == 1 and sig.name in stops[0]["message"]
    assert any(e["kind"] == "stop" for e in log.events) and log.meta is not None
    assert log.meta["process"] == summary["process"]
    assert_stopped_at_rest_within_limits(log.cycles)
    code, err = report_of(run.log, tmp_path, capsys)
    assert code == 0 and "truncated" not in err, err


def test_a_run_killed_outright_leaves_a_log_that_log_report_reads_as_truncated(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    run = launch(tmp_path)
    try:
        # wait until the writer has flushed a few chunks (the chunk being filled is lost on a kill)
        deadline = time.monotonic() + 120
        while run.log.stat().st_size < 600_000 and time.monotonic() < deadline and run.proc.poll() is None:
            time.sleep(0.1)
        assert run.log.stat().st_size >= 600_000
        run.proc.send_signal(signal.SIGKILL)
        run.proc.wait()
    finally:
        cleanup(run)  # the orphaned loop stops to rest by itself (its parent is gone), then exits
    assert run.proc.returncode == -signal.SIGKILL
    log = load_log(run.log, allow_truncated=True)
    assert log.truncated is not None and log.stats is None and len(log.cycles) > 100
    assert [c["k"] for c in log.cycles] == list(range(len(log.cycles)))  # a clean prefix, nothing garbled
    code, err = report_of(run.log, tmp_path, capsys)
    assert code == 0
    assert f"{run.log} is truncated (no summary/footer); read {len(log.cycles)} cycles up to t=" in err
    assert len(err.strip().splitlines()) == 1


# -- the handler itself (no subprocess) -------------------------------------------------------------
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM, signal.SIGHUP])
def test_before_the_loop_starts_a_signal_abandons_the_run_with_128_plus_its_number(
    sig: signal.Signals, capfd: pytest.CaptureFixture[str]
) -> None:
    before = signal.getsignal(sig)
    with pytest.raises(RunInterrupted) as exc, StopSignals():
        os.kill(os.getpid(), sig)
        time.sleep(1.0)  # the handler runs here
    assert exc.value.report() == 128 + sig
    err = capfd.readouterr().err
    assert err.strip() == f"lapwrench run: stopped by {sig.name} before the loop started; the robot was not moved"
    assert signal.getsignal(sig) is before  # restored


def test_once_armed_the_first_signal_requests_the_stop_and_later_ones_are_ignored(
    capfd: pytest.CaptureFixture[str],
) -> None:
    with StopSignals() as signals:
        stop = signals.arm()
        assert not stop.is_set()
        os.kill(os.getpid(), signal.SIGHUP)
        assert stop.wait(5.0)
        os.kill(os.getpid(), signal.SIGINT)  # no KeyboardInterrupt: the stop goes on
        time.sleep(0.2)
    assert stop.reason == "SIGHUP" and signals.received == ["SIGHUP", "SIGINT"]
    err = capfd.readouterr().err
    assert "SIGHUP: stopping to rest" in err and "stopping, please wait (SIGINT ignored)" in err
