"""lapwrench.hardware.run_rt: ``lapwrench run``'s default path, which builds the real-time child's spec from
the arguments, serves it, and turns its outcome into the summary line and the exit code.

The real-time process is replaced by a recording stand-in (the child itself is test_rt_process.py's and
tests/hardware/rt's): what reaches it from the arguments, and what the command makes of each outcome
it can report (done, alarm, a signal to the child, a robot or device error, an error at start-up).
"""

from __future__ import annotations

import argparse
import functools
import json
from pathlib import Path
from typing import Any, ClassVar

import pytest

from lapwrench.config import Config
from lapwrench.hardware import cli as hw
from lapwrench.hardware.devices import DryRunScript
from lapwrench.hardware.log import read_log
from lapwrench.hardware.rt import RtProcessError, RtResult, franka_factory, sim_factory
from lapwrench.hardware.rt.spec import RtSpec
from lapwrench.hardware.run_rt import run_process
from lapwrench.loop_stats import LoopStats


def rt_error(kind: str, message: str) -> RtProcessError:
    e = RtProcessError(message)
    e.kind = kind  # type: ignore[attr-defined]
    return e


class FakeRtProcess:
    """Stands in for RtProcess: records what it was given and plays ``outcome``."""

    made: ClassVar[list[FakeRtProcess]] = []
    outcome: ClassVar[dict[str, Any]] = {}

    def __init__(self, spec: RtSpec, *, tactile: Any = None, inputs: Any = None, child_timeout: float = 0.5) -> None:
        self.spec, self.tactile, self.inputs, self.child_timeout = spec, tactile, inputs, child_timeout
        self.bus_name = "fake"
        self.detector_pid: int | None = None
        self.logger: Any = None
        self.run_args: tuple[Any, ...] | None = None
        self.closed = 0
        FakeRtProcess.made.append(self)

    def start(self) -> dict[str, Any]:
        if "start_error" in self.outcome:
            raise self.outcome["start_error"]
        return {"robot": "fake robot", "devices": {"ft": "fake F/T"}, "rt_problems": self.outcome.get("problems", []),
                "pid": 1}

    def set_logger(self, logger: Any) -> None:
        self.logger = logger

    def run(self, duration: float | None, stop: Any, *, script_t0: float | None = None) -> RtResult:
        self.run_args = (duration, stop, script_t0)
        if "run_error" in self.outcome:
            raise self.outcome["run_error"]
        stats = LoopStats(cycles=1000, robot_time=1.0, alarm=self.outcome.get("alarm"), stopped_at_rest=True)
        report = {"ft_fresh_cycles": 750, "hook_cycles": 1000, "log_dropped": 3, **self.outcome.get("report", {})}
        return RtResult(stats, report)

    def close(self) -> None:
        self.closed += 1


@pytest.fixture
def fake(monkeypatch: pytest.MonkeyPatch) -> type[FakeRtProcess]:
    import lapwrench.hardware.rt as rt

    FakeRtProcess.made = []
    FakeRtProcess.outcome = {}
    monkeypatch.setattr(rt, "RtProcess", FakeRtProcess)
    return FakeRtProcess


def args_of(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    hw.add_run_arguments(p)
    return p.parse_args(argv)


ROBOT = ["--robot-ip", "192.0.2.9", "--duration", "1.5"]


def run(argv: list[str], cfg: Config, capsys: pytest.CaptureFixture[str]) -> tuple[int, dict[str, Any] | None, str]:
    code = run_process(args_of(argv), cfg)
    out = capsys.readouterr()
    lines = out.out.strip().splitlines()
    return code, json.loads(lines[-1]) if lines else None, out.err


def test_the_robot_path_hands_the_arguments_to_the_child(fake: type[FakeRtProcess], panda_cfg: Config,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    argv = [*ROBOT, "--rt-priority", "0", "--rt-cpus", "0,1", "--realtime", "ignore", "--no-external-force",
            "--ext-wrench-sign", "environment_on_robot", "--feeder-timeout", "0.7", "--max-misses", "4"]
    code, summary, err = run(argv, panda_cfg, capsys)
    assert code == 0
    (rp,) = fake.made
    spec = rp.spec
    assert isinstance(spec.robot_factory, functools.partial) and spec.robot_factory.func is franka_factory
    assert spec.robot_factory.keywords == {
        "robot_ip": "192.0.2.9", "kind": "panda", "realtime": "ignore", "ext_wrench_sign": "environment_on_robot",
        "report_external_force": False,
    }
    assert spec.rt.fifo_priority is None and spec.rt.cpus == (0, 1)  # 0: don't ask for SCHED_FIFO
    assert spec.ft is None and not spec.tactile and not spec.instruments and spec.script is None
    assert spec.duration == 1.5 and spec.feeder_timeout == 0.7 and spec.supervisor.max_consecutive_misses == 4
    assert not spec.log_cycles  # no --log, no --foxglove: the child does not record cycles
    assert rp.child_timeout == 0.5  # a real robot: a hung child is noticed within 0.5 s
    assert rp.run_args is not None and rp.run_args[0] == 1.5 and rp.run_args[2] is None
    assert rp.closed == 1  # closed on the way out
    assert summary is not None and summary["process"] == "rt" and summary["stop_reason"] == "duration"
    assert summary["cycles"] == 1000 and summary["log_dropped_records"] == 3 and summary["ft_fresh_pct"] is None
    assert "fake robot ready" in err


@pytest.mark.parametrize(("outcome", "code", "reason"), [
    ({}, 0, "duration"),
    ({"alarm": "rcm_error: 6 mm"}, 1, "alarm"),
    ({"report": {"stop_signal": "SIGTERM"}}, 0, "SIGTERM (to the real-time process)"),
])
def test_the_summary_and_the_exit_code_follow_the_outcome(fake: type[FakeRtProcess], panda_cfg: Config,
                                                          capsys: pytest.CaptureFixture[str], outcome: dict[str, Any],
                                                          code: int, reason: str) -> None:
    fake.outcome = outcome
    got, summary, _ = run(ROBOT, panda_cfg, capsys)
    assert got == code and summary is not None and summary["stop_reason"] == reason
    assert summary["alarm"] == outcome.get("alarm")


@pytest.mark.parametrize(("where", "kind", "code", "words"), [
    ("run_error", "died", 3, "robot error: the child died"),
    ("run_error", "hung", 3, "robot error: the child died"),
    ("start_error", "robot", 3, "robot error: the child died"),
    ("start_error", "device", 2, "device not ready: the child died"),
])
def test_a_child_error_is_one_line_and_an_exit_code(fake: type[FakeRtProcess], panda_cfg: Config,
                                                    capsys: pytest.CaptureFixture[str], where: str, kind: str,
                                                    code: int, words: str) -> None:
    fake.outcome = {where: rt_error(kind, "the child died")}
    got, summary, err = run(ROBOT, panda_cfg, capsys)
    assert got == code and summary is None  # no summary of a run that failed
    assert f"lapwrench run: {words}" in err and "Traceback" not in err
    assert fake.made[0].closed == 1  # the child is closed all the same


def test_child_start_up_warnings_are_printed(fake: type[FakeRtProcess], panda_cfg: Config,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    fake.outcome = {"problems": ["SCHED_FIFO priority 80 not permitted"]}
    code, _, err = run(ROBOT, panda_cfg, capsys)
    assert code == 0 and "lapwrench run: warning: SCHED_FIFO priority 80 not permitted" in err


@pytest.mark.parametrize("cpus", ["a,b", "1,,2", "0;1"])
def test_a_cpu_list_that_is_not_integers_is_an_argument_error(fake: type[FakeRtProcess], panda_cfg: Config,
                                                              capsys: pytest.CaptureFixture[str], cpus: str) -> None:
    args = args_of(ROBOT)
    args.rt_cpus = cpus  # as a program calling run_process would pass it (no argparse type)
    assert run_process(args, panda_cfg) == 2
    assert "CPU list must be comma-separated integers" in capsys.readouterr().err
    assert not fake.made  # refused before any child


def test_a_missing_tactile_port_is_named_before_any_child(fake: type[FakeRtProcess], panda_cfg: Config,
                                                          capsys: pytest.CaptureFixture[str]) -> None:
    code, summary, err = run([*ROBOT, "--tactile", "/dev/lapwrench-no-such-tty"], panda_cfg, capsys)
    assert code == 2 and summary is None and "/dev/lapwrench-no-such-tty" in err and not fake.made


def test_frankysim_unavailable_is_named(fake: type[FakeRtProcess], fr3_cfg: Config, monkeypatch: pytest.MonkeyPatch,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    import lapwrench.hardware.frankysim as fs

    monkeypatch.setattr(fs, "frankysim_available", lambda: "ImportError: no module named pylibfranka")
    code, summary, err = run(["--frankysim", "--duration", "1"], fr3_cfg, capsys)
    assert code == 2 and summary is None and not fake.made
    assert "--frankysim: franky-sim/pylibfranka unavailable: ImportError" in err


def test_the_dry_run_wires_the_simulated_devices_and_the_script_into_the_child(
    fake: type[FakeRtProcess], panda_cfg: Config, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "run.mcap"
    code, summary, _ = run(["--dry-run", "--duration", "2", "--log", str(log)], panda_cfg, capsys)
    assert code == 0
    (rp,) = fake.made
    spec = rp.spec
    assert spec.robot_factory.func is sim_factory and spec.robot_factory.keywords == {"realtime": True}
    assert spec.ft is not None and spec.ft.kind == "hex" and spec.ft.host == "127.0.0.1" and spec.ft.tare
    assert spec.tactile and rp.tactile is not None  # the tactile frames reach the parent's buffer to feed
    assert isinstance(spec.script, DryRunScript) and spec.log_cycles
    assert rp.child_timeout == 5.0  # a simulated robot on a loaded machine: a longer heartbeat timeout
    assert rp.run_args is not None and rp.run_args[2] == spec.script.t0  # the child's script clock is the parent's
    assert summary is not None and summary["ft_fresh_pct"] == 75.0  # 750 fresh F/T samples in 1000 cycles
    assert rp.logger is not None
    _, _, meta = read_log(log)
    assert meta["process"] == "rt" and meta["dry_run"] is True and meta["frankysim"] is False
    assert meta["robot"] == "fake robot"
