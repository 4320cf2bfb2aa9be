"""The detector in its own process: frames in through shared memory, points out; its death stops the arm."""

from __future__ import annotations

import os
import signal
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hardware.support import MemoryLogger, failing_detector, fixed_detector, rt_process, rt_spec

from lapwrench.hardware.detector_process import DetectorProcess
from lapwrench.hardware.rt import RtProcessError, bus_layout
from lapwrench.hardware.shm import Bus

pytestmark = pytest.mark.slow  # the detector in its own process

SIZE = (64, 48)


@pytest.fixture
def bus() -> Iterator[Bus]:
    b = Bus.create(bus_layout())
    try:
        yield b
    finally:
        b.close()


def wait_for(cond: Any, timeout: float = 20.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if cond():
            return True
        time.sleep(0.01)
    return cond()


def test_points_come_back_stamped_with_the_frame_time(bus: Bus) -> None:
    with DetectorProcess(fixed_detector, bus.name, SIZE) as det:
        assert det.pid != os.getpid() and det.info["detector"] == "FixedDetector"
        slot = bus.slot("instruments")
        stamp = time.monotonic() - 0.05
        det.publish(np.full((48, 64, 3), 90, np.uint8), stamp)
        assert wait_for(lambda: slot.seq > 0)
        out = np.empty_like(slot.data)
        _, t, n = slot.read_into(out)
        assert t == stamp and n == 2
        assert out[:2].tolist() == [[400.0, 300.0], [250.0, 200.0]]
        # a detection that raises is counted; the process keeps going and the points stay as they were
        det.publish(np.zeros((48, 64, 3), np.uint8))
        assert wait_for(lambda: det.errors == 1)
        assert det.alive and slot.read_into(out)[1] == stamp
        det.publish(np.full((48, 64, 3), 90, np.uint8))
        assert wait_for(lambda: det.frames_done == 2)


def test_a_detector_that_cannot_be_built_is_named(bus: Bus) -> None:
    det = DetectorProcess(failing_detector, bus.name, SIZE)
    with pytest.raises(RtProcessError, match="no such model"):
        det.start()
    assert not det.alive


def test_a_killed_detector_stops_the_arm_to_rest(panda_cfg: Any) -> None:
    spec = rt_spec(panda_cfg, duration=6.0, tactile=False, instruments=True)
    stop = threading.Event()
    log = MemoryLogger()
    with rt_process(spec, logger=log) as rp:
        det = DetectorProcess(fixed_detector, rp.bus_name, SIZE).start()
        try:
            rp.detector_pid = det.pid

            def camera() -> None:
                while not stop.is_set():
                    det.publish(np.full((48, 64, 3), 90, np.uint8))
                    stop.wait(0.04)

            threading.Thread(target=camera, daemon=True).start()
            rp.start()
            threading.Timer(1.0, lambda: os.kill(det.pid, signal.SIGKILL)).start()
            res = rp.run()
        finally:
            stop.set()
            det.stop()
    st = res.stats
    assert st.alarm is not None and st.alarm.startswith("peer_died") and "detector" in st.alarm, st.alarm
    assert st.stopped_at_rest and st.robot_time < 5.0
    # before the kill the detections reached the controller through the instruments slot
    seen = [c.instruments for c in log.cycles if c.instruments is not None]
    assert seen and all(p.tolist() == [[400.0, 300.0], [250.0, 200.0]] for p in seen)


def test_lapwrench_run_with_a_camera_runs_the_detector_in_its_own_process(tmp_path: Path) -> None:
    import argparse
    import json

    import cv2

    from lapwrench.hardware import cli as hw
    from lapwrench.hardware.log import read_log
    from lapwrench.perception import SHIPPED_MODEL
    from lapwrench.perception.synthetic import draw_instrument_scene

    video = tmp_path / "scope.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (640, 480))
    for i in range(10):
        writer.write(cv2.cvtColor(draw_instrument_scene((640, 480), seed=i)[0], cv2.COLOR_RGB2BGR))
    writer.release()
    p = argparse.ArgumentParser()
    hw.add_run_arguments(p)
    log = tmp_path / "run.mcap"
    args = p.parse_args(
        ["--dry-run", "--duration", "2", "--camera", str(video), "--detector", str(SHIPPED_MODEL), "--log", str(log),
         "--max-misses", "0", "--rt-priority", "0",
         # generous hang timeouts: this test is about detections reaching the loop, on a busy CI machine
         "--feeder-timeout", "5", "--detector-timeout", "5"]
    )
    import contextlib
    import io

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        code = hw.run_main(args)
    assert code == 0
    summary = json.loads(out.getvalue().strip().splitlines()[-1])
    assert summary["process"] == "rt" and summary["stopped_at_rest"]
    cycles, _events, meta = read_log(log)
    assert "camera" in meta["devices"]
    # the detections reached the loop (image points in the records) and the tracking cue engaged
    assert any(c["instruments"] for c in cycles)
    assert any("tracking" in c["mode"] for c in cycles)
