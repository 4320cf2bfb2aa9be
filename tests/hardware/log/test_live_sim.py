"""lapwrench.hardware.log.live_sim: simulated runs streamed to a run logger (demo/ui --foxglove)."""

from __future__ import annotations

import itertools
from pathlib import Path

from lapwrench.config import load
from lapwrench.hardware.log import RunLogger, read_log
from lapwrench.hardware.log.live_sim import SimTelemetry
from lapwrench.sim.loop import ClosedLoop, observe_cycles


def test_sim_telemetry_sends_every_tenth_cycle_and_keeps_the_clock_running_across_loops(tmp_path: Path) -> None:
    path = tmp_path / "sim.mcap"
    with RunLogger(path, None) as logger, observe_cycles(SimTelemetry(logger, every=10)):
        for _ in range(2):  # two runs, each starting its clock at 0
            loop = ClosedLoop(load())
            for _ in range(200):
                loop.step(0.0)
    outside = ClosedLoop(load())  # built after the block: not observed
    outside.step(0.0)
    cycles = read_log(path)[0]
    t = [c["t"] for c in cycles]
    assert 38 <= len(t) <= 42 and all(b > a for a, b in itertools.pairwise(t))
    assert t[-1] > 0.35  # the second run continued after the first (0.2 s each)


def test_rendered_frames_reach_the_log_at_5_hz_of_simulated_time(tmp_path: Path) -> None:
    from lapwrench.hardware.log import log_topics
    from lapwrench.hardware.log.topics import IMAGE_TOPIC

    path = tmp_path / "frames.mcap"
    with RunLogger(path, None) as logger, observe_cycles(SimTelemetry(logger)):
        loop = ClosedLoop(load(), detector="projected")  # renders the camera at 25 fps
        for _ in range(1000):  # 1 s
            loop.step(0.0)
    assert 4 <= log_topics(path)[IMAGE_TOPIC].messages <= 6
