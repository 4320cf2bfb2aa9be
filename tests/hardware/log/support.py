"""Helpers of the run-log tests: cycle records like the runner's, a short log, ``log-report``."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lapwrench.hardware import log as runlog
from lapwrench.hardware.log import CycleRecord, RunLogger, iter_messages, log_report_main
from lapwrench.robot.model import RobotModel
from lapwrench.virtual import DEFAULT_Q0

N_LONG = 3000  # cycles: 4 chunks of foxglove-sdk's default size, so a cut can fall between and inside them
Q0 = np.asarray(DEFAULT_Q0, dtype=float)


def record(i: int, **over: Any) -> CycleRecord:
    """Cycle ``i`` like the runner's (1 kHz session time), with ``over`` replacing fields."""
    base: dict[str, Any] = dict(
        t=i * 1e-3, robot_time=i * 1e-3, k=i, q=Q0 + 1e-3 * i, dq=np.zeros(7), tau_J=np.ones(7),
        external_force=None, ft_force=np.array([1.0, 2.0, 3.0]), ft_torque=np.zeros(3), tactile=np.zeros(64),
        instruments=np.array([[10.0, 20.0]]),
        wrenches={"rcm": np.arange(6.0), "interaction": np.array([0, 0, 0, 0, 0, -5.0]), "tracking": np.zeros(6)},
        mode="handle", delta=1.2, contacts=64, p_R=np.array([0.45, 0.0, 0.25]), e_R=np.array([1e-3, 0, 0]),
        rcm_error=1e-3, rcm_error_measured=2e-3, q_ref=np.zeros(7), q_cmd=np.zeros(7), supervisor="running",
        alarm=False, compute_us=150.0, cycle_us=1000.0,
    )  # fmt: skip
    base.update(over)
    return CycleRecord(**base)


def write(path: Path, n: int, model: RobotModel | None = None, **kw: Any) -> RunLogger:
    with RunLogger(path, {"robot": "test", "n": n}, model=model, **kw) as log:
        for k in range(n):
            log.cycle(record(k, p_G=np.array([0.45, 0.0, 0.2])))
        log.event(0.05, "rcm_error", "RCM error 12 mm; holding")
    return log


def report(path: Path, out: Path, capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = log_report_main(argparse.Namespace(log=str(path), out=str(out)))
    printed = capsys.readouterr()
    assert "Traceback" not in printed.out + printed.err
    return code, printed.out, printed.err


def tf_messages(path: Path) -> list[dict[str, Any]]:
    """The frame-transform messages of the log at ``path``."""
    return [m for _, m in iter_messages(path, [runlog.TF_TOPIC])]
