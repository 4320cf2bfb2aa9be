"""The MCAP sink: NaN and bad records do not break the file."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from hardware.log.support import record, tf_messages

from lapwrench.hardware.log import (
    RunLogger,
    log_report_main,
    read_log,
)
from lapwrench.robot.model import RobotModel


def test_nan_and_bad_records_do_not_break_the_file(tmp_path: Path, panda: RobotModel) -> None:
    path = tmp_path / "run.mcap"
    nan3 = np.array([np.nan, 1.0, np.inf])
    with RunLogger(path, {"robot": "test", "x": float("nan")}, model=panda) as log:
        log.cycle(record(0, q=np.full(7, np.nan), ft_force=nan3, rcm_error=float("nan"), delta=float("inf"),
                         wrenches={"rcm": np.full(6, np.nan)}, instruments=np.array([[np.nan, 2.0]])))  # fmt: skip
        log.cycle(record(1, q="not a joint vector"))  # cannot be converted: counted, skipped
        log.cycle(record(2, k=np.int64(2), alarm=np.bool_(True), p_G=np.array([np.nan, 0, 0])))
        log.event(float("nan"), "odd", "an event without a time")
    assert log.errors == 1 and "ValueError" in str(log.stats()["first_error"])
    cycles, _, meta = read_log(path)
    assert meta == {"robot": "test", "x": None}
    assert [c["k"] for c in cycles] == [0, 2]
    c0 = cycles[0]
    assert c0["q"] == [None] * 7 and c0["ft_force"] == [None, 1.0, None] and c0["rcm_error"] is None
    assert c0["delta"] is None and c0["wrenches"]["rcm"] == [None] * 6 and c0["instruments"] == [[None, 2.0]]
    assert cycles[1]["alarm"] is True and cycles[1]["p_G"] == [None, 0.0, 0.0]
    tfs = tf_messages(path)  # the NaN q gave no transforms; the last cycle did (without G)
    assert len(tfs) == 1 and "lap_G" not in {t["child_frame_id"] for t in tfs[0]["transforms"]}
    assert log_report_main(argparse.Namespace(log=str(path), out=str(tmp_path / "report"))) == 0
