"""Asynchronous detection: 25 fps capture, modelled latency, capture stamps, age, empty = W_c 0."""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.perception import Detection, DetectorConfig
from lapwrench.perception.async_detect import SimulatedAsyncDetector, ThreadedAsyncDetector
from lapwrench.robot.model import RobotModel
from lapwrench.sensors import InputValidator, InstrumentObservation, SensorFrame

FRAME = np.zeros((480, 640, 3), np.uint8)


class FakeDetector:
    """One detection at u = 100 + frame index (encoded in pixel (0, 0)), or none for index 255."""

    def __init__(self, delay: float = 0.0) -> None:
        self.config = DetectorConfig()
        self.calls = 0
        self.delay = delay

    def detect(self, image: np.ndarray) -> list[Detection]:
        self.calls += 1
        if self.delay:
            time.sleep(self.delay)
        k = int(image[0, 0, 0])
        if k == 255:
            return []
        return [Detection(box=(90.0 + k, 50.0, 110.0 + k, 70.0), score=0.9, class_id=0, point=(100.0 + k, 60.0))]


def frame(k: int) -> np.ndarray:
    f = FRAME.copy()
    f[0, 0, 0] = k
    return f


def run_loop(
    adet: SimulatedAsyncDetector, seconds: float, frames: list[int] | None = None
) -> tuple[list[tuple[float, InstrumentObservation]], int]:
    """1 kHz loop; returns per-tick (t, observation). Frame k is the k-th captured one."""
    out = []
    count = {"k": 0}

    def render() -> np.ndarray:
        k = count["k"] if frames is None else frames[count["k"]]
        count["k"] += 1
        return frame(k)

    for i in range(round(seconds * 1000)):
        t = i * 0.001
        adet.offer(t, render)
        out.append((t, adet.observation(t)))
    return out, count["k"]


def test_captures_at_25_fps_and_publishes_after_the_latency() -> None:
    det = FakeDetector()
    adet = SimulatedAsyncDetector(det, frame_rate=25.0, latency=0.03)
    ticks, n_frames = run_loop(adet, 0.2)
    assert n_frames == det.calls == 5  # t = 0, 40, 80, 120, 160 ms: rendering only when due
    by_t = {round(t * 1000): obs for t, obs in ticks}
    assert by_t[0].points.shape == (0, 2) and by_t[29].points.shape == (0, 2)  # nothing yet: W_c = 0
    assert by_t[30].points.tolist() == [[100.0, 60.0]] and by_t[30].stamp == 0.0
    assert by_t[69].stamp == 0.0  # frame 1 (captured at 40 ms) not out yet: age 69 ms
    assert by_t[70].points.tolist() == [[101.0, 60.0]] and by_t[70].stamp == pytest.approx(0.04)
    res = adet.latest(0.199)
    assert res.capture_time == pytest.approx(0.16) and res.latency == pytest.approx(0.03)
    assert res.age(0.199) == pytest.approx(0.039)


def test_latency_longer_than_the_frame_period_pipelines() -> None:
    adet = SimulatedAsyncDetector(FakeDetector(), frame_rate=25.0, latency=0.1)
    ticks, _ = run_loop(adet, 0.25)
    by_t = {round(t * 1000): obs for t, obs in ticks}
    assert by_t[99].points.shape == (0, 2)
    assert by_t[100].stamp == 0.0 and by_t[140].stamp == pytest.approx(0.04)
    assert by_t[249].stamp == pytest.approx(0.12)  # available at 220 ms; 160's arrives at 260


def test_no_detection_gives_empty_points_with_the_capture_stamp() -> None:
    adet = SimulatedAsyncDetector(FakeDetector(), latency=0.0)
    adet.offer(0.0, frame(255))
    obs = adet.observation(0.0)
    assert obs.points.shape == (0, 2) and obs.stamp == 0.0


def test_max_age_drops_stale_results() -> None:
    adet = SimulatedAsyncDetector(FakeDetector(), latency=0.01, max_age=0.05)
    adet.offer(0.0, frame(3))
    assert adet.observation(0.02).points.shape == (1, 2)
    assert adet.observation(0.051).points.shape == (0, 2)  # camera stalled: older than max_age


def test_controller_validator_drops_old_detections() -> None:
    cfg = load()
    limits = RobotModel().limits  # not used for image points
    val = InputValidator(cfg.interaction, cfg.camera, limits, max_image_age=cfg.inputs.max_image_age)
    adet = SimulatedAsyncDetector(FakeDetector(), latency=0.03)
    adet.offer(0.0, frame(0))
    fresh = val.validate(SensorFrame(time=0.05, instruments=adet.observation(0.05)))
    assert fresh.instruments is not None and fresh.instruments.points.shape == (1, 2)
    t_old = cfg.inputs.max_image_age + 0.01
    stale = val.validate(SensorFrame(time=t_old, instruments=adet.observation(t_old)))
    assert stale.instruments is None and "older than" in stale.events[0].message


def test_measured_latency_is_the_compute_time() -> None:
    adet = SimulatedAsyncDetector(FakeDetector(delay=0.01), latency="measured")
    adet.offer(1.0, frame(0))
    assert adet.latest(1.0) is None
    res = adet.latest(1.5)
    assert res.compute_time >= 0.009 and res.latency == pytest.approx(res.compute_time)


def test_observation_type_and_reset() -> None:
    adet = SimulatedAsyncDetector(FakeDetector(), latency=0.0)
    adet.offer(0.0, frame(0))
    assert isinstance(adet.observation(0.0), InstrumentObservation)
    adet.reset()
    assert adet.latest(1.0) is None and adet.due(1.0)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"frame_rate": 0.0}, "frame_rate"), ({"latency": -0.1}, "latency"), ({"latency": "soon"}, "latency"),
     ({"max_age": 0.0}, "max_age")],
)
def test_bad_arguments(kwargs: dict[str, Any], match: str) -> None:
    with pytest.raises(ValueError, match=match):
        SimulatedAsyncDetector(FakeDetector(), **kwargs)


def test_threaded_worker_stamps_capture_time_and_keeps_the_newest_frame() -> None:
    det = FakeDetector(delay=0.05)
    clock_lock = threading.Lock()
    now = {"t": 10.0}

    def clock() -> float:
        with clock_lock:
            return now["t"]

    with ThreadedAsyncDetector(det, frame_rate=25.0, clock=clock) as adet:
        assert adet.observation(clock()).points.shape == (0, 2)
        assert adet.offer(10.0, frame(1))
        time.sleep(0.01)  # worker busy with frame 1
        assert adet.offer(10.04, frame(2))
        assert adet.offer(10.08, frame(3))  # replaces frame 2 (never detected)
        assert not adet.offer(10.09, frame(4))  # not due
        res = adet.wait_for_result(10.08, timeout=5.0)
        assert res is not None and res.capture_time == pytest.approx(10.08)
        assert res.points().tolist() == [[103.0, 60.0]]
        assert adet.frames_dropped == 1 and det.calls == 2
        obs = adet.observation(10.1)
        assert obs.stamp == pytest.approx(10.08)


def test_threaded_worker_error_surfaces() -> None:
    class Boom:
        config = DetectorConfig()

        def detect(self, image: np.ndarray) -> list[Detection]:
            raise RuntimeError("model exploded")

    adet = ThreadedAsyncDetector(Boom())
    try:
        adet.offer(0.0, FRAME)
        with pytest.raises(RuntimeError, match="model exploded"):
            adet.wait_for_result(0.0, timeout=5.0)
        with pytest.raises(RuntimeError, match="worker failed"):
            adet.offer(1.0, FRAME)
    finally:
        adet.close()
