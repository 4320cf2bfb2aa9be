"""lapwrench.hardware.run_inprocess: ``lapwrench run --in-process``, the loop in the command's own process.

One short dry run end to end (the simulated robot, F/T box and tactile array); the rest with the loop
and the Franka driver replaced by recording stand-ins: what the arguments become (driver, supervisor,
source ages), and what the command makes of each outcome (done, alarm, a robot that fails to connect
or fails mid-run, a device that is not there): a summary line and exit code, or one error line, and
everything opened closed.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import pytest

from lapwrench.config import Config
from lapwrench.hardware import cli as hw
from lapwrench.hardware.log import read_log
from lapwrench.hardware.run_inprocess import run_in_process
from lapwrench.loop_stats import LoopStats
from lapwrench.robot.errors import RobotError


def args_of(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    hw.add_run_arguments(p)
    return p.parse_args(argv)


def run(argv: list[str], cfg: Config, capsys: pytest.CaptureFixture[str]) -> tuple[int, dict[str, Any] | None, str]:
    code = run_in_process(args_of(["--in-process", *argv]), cfg)
    out = capsys.readouterr()
    lines = out.out.strip().splitlines()
    return code, json.loads(lines[-1]) if lines else None, out.err


class FakeFranka:
    """Records the driver's arguments; never connects."""

    made: ClassVar[list[FakeFranka]] = []

    def __init__(self, robot_ip: str, **kw: Any) -> None:
        self.robot_ip, self.kw = robot_ip, kw
        FakeFranka.made.append(self)

    @property
    def device(self) -> str:
        return f"fake Franka at {self.robot_ip}"


class FakeLoop:
    """Records what the loop is built from and plays ``outcome``."""

    made: ClassVar[list[FakeLoop]] = []
    outcome: ClassVar[dict[str, Any]] = {}

    def __init__(self, robot: Any, ctrl: Any, sup: Any, sources: Any, ages: Any = None) -> None:
        self.robot, self.ctrl, self.sup, self.sources, self.ages = robot, ctrl, sup, sources, ages
        self.logger: Any = None
        self.ran: tuple[Any, Any] | None = None
        FakeLoop.made.append(self)

    def start(self) -> None:
        if "start_error" in self.outcome:
            raise self.outcome["start_error"]

    def run(self, duration: float | None, stop: Any) -> LoopStats:
        self.ran = (duration, stop)
        if "run_error" in self.outcome:
            raise self.outcome["run_error"]
        return LoopStats(cycles=10, robot_time=0.01, alarm=self.outcome.get("alarm"), stopped_at_rest=True)

    def session_time(self, t: float) -> float:
        return 0.0


@pytest.fixture
def fakes(monkeypatch: pytest.MonkeyPatch) -> type[FakeLoop]:
    import lapwrench.hardware.franka as franka
    import lapwrench.hardware.runner as runner

    FakeLoop.made, FakeLoop.outcome, FakeFranka.made = [], {}, []
    monkeypatch.setattr(runner, "ControlLoop", FakeLoop)
    monkeypatch.setattr(franka, "FrankaRobot", FakeFranka)
    return FakeLoop


ROBOT = ["--robot-ip", "192.0.2.9", "--duration", "0.5"]


def test_the_robot_path_builds_the_driver_the_supervisor_and_the_ages_from_the_arguments(
    fakes: type[FakeLoop], panda_cfg: Config, capsys: pytest.CaptureFixture[str]
) -> None:
    from lapwrench.hardware.franka import Payload

    argv = [*ROBOT, "--realtime", "ignore", "--no-external-force", "--ext-wrench-sign", "environment_on_robot",
            "--cycle-budget-us", "700", "--max-misses", "5", "--max-rcm-error", "0.004", "--ft-max-age", "0.02",
            "--tactile-max-age", "0.3", "--camera-max-age", "0.4"]
    code, summary, err = run(argv, panda_cfg, capsys)
    assert code == 0
    (loop,) = fakes.made
    (robot,) = FakeFranka.made
    assert loop.robot is robot and robot.robot_ip == "192.0.2.9"
    assert robot.kw == {"kind": "panda", "realtime": "ignore", "ext_wrench_sign": "environment_on_robot",
                        "report_external_force": False, "load": Payload.from_scope(loop.ctrl.model.scope),
                        "dt": panda_cfg.robot.dt}
    cfg = loop.sup.cfg
    assert cfg.cycle_budget == pytest.approx(700e-6) and cfg.max_consecutive_misses == 5
    assert cfg.max_rcm_error == 0.004
    assert (loop.ages.ft, loop.ages.tactile, loop.ages.instruments) == (0.02, 0.3, 0.4)
    assert loop.sources.ft is None and loop.sources.tactile is None and loop.sources.instruments is None
    assert loop.ran is not None and loop.ran[0] == 0.5
    assert summary is not None and summary["process"] == "in-process" and summary["stop_reason"] == "duration"
    assert summary["cycles"] == 10 and summary["log"] is None
    assert "fake Franka at 192.0.2.9 connected" in err


@pytest.mark.parametrize(("outcome", "code", "words"), [
    ({"alarm": "peer_hung: tactile"}, 1, None),
    ({"start_error": RobotError("cannot connect to 192.0.2.9")}, 3, "robot error: cannot connect to 192.0.2.9"),
    ({"run_error": RobotError("communication_constraints_violation")}, 3,
     "robot error: communication_constraints_violation"),
])
def test_each_outcome_is_a_summary_or_one_error_line(fakes: type[FakeLoop], panda_cfg: Config, tmp_path: Path,
                                                     capsys: pytest.CaptureFixture[str], outcome: dict[str, Any],
                                                     code: int, words: str | None) -> None:
    fakes.outcome = outcome
    log = tmp_path / "run.mcap"
    got, summary, err = run([*ROBOT, "--log", str(log)], panda_cfg, capsys)
    assert got == code and "Traceback" not in err
    if words is None:
        assert summary is not None and summary["alarm"] == outcome["alarm"] and summary["stop_reason"] == "alarm"
    else:
        assert summary is None and f"lapwrench run: {words}" in err
    _, _, meta = read_log(log)  # opened before the robot connects, finalized whatever the outcome
    assert meta["process"] == "in-process" and meta["dry_run"] is False


@pytest.mark.parametrize(("extra", "words"), [
    (["--tactile", "/dev/lapwrench-no-such-tty"], "/dev/lapwrench-no-such-tty"),
    (["--ft", "bogus://192.0.2.9"], "bogus://192.0.2.9"),
])
def test_a_device_that_is_not_there_is_named_before_the_robot(fakes: type[FakeLoop], panda_cfg: Config,
                                                              capsys: pytest.CaptureFixture[str], extra: list[str],
                                                              words: str) -> None:
    code, summary, err = run([*ROBOT, *extra], panda_cfg, capsys)
    assert code == 2 and summary is None and words in err and err.startswith("lapwrench run: ")
    assert not fakes.made and not FakeFranka.made  # neither the loop nor the driver was built


@pytest.mark.slow  # a dry run: the simulated arm, F/T box and tactile array, on the wall clock
def test_a_dry_run_runs_the_loop_here_and_ends_at_rest(panda_cfg: Config, tmp_path: Path,
                                                       capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "dry.mcap"
    code, summary, err = run(["--dry-run", "--duration", "0.4", "--log", str(log), "--max-misses", "0"], panda_cfg,
                             capsys)
    assert code == 0, err
    assert summary is not None and summary["process"] == "in-process" and summary["stop_reason"] == "duration"
    assert summary["cycles"] > 0 and summary["alarm"] is None and summary["stopped_at_rest"]
    assert "simulated panda (MuJoCo) connected" in err
    cycles, events, meta = read_log(log)
    assert meta["process"] == "in-process" and meta["dry_run"] is True
    assert set(meta["devices"]) == {"ft", "tactile"}
    assert len(cycles) == summary["cycles"] and any(e["kind"] == "start" for e in events)
    assert all(np.all(np.isfinite(c["q_cmd"])) for c in cycles)
