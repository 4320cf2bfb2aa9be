"""lapwrench.hardware.log.live: the log's channels served to Foxglove over a WebSocket, checked with a
real WebSocket client speaking Foxglove's protocol (foxglove.sdk.v1)."""

from __future__ import annotations

import asyncio
import json
import socket
import struct
import time
from pathlib import Path
from typing import Any

import pytest
from hardware.log.support import record

from lapwrench.hardware.log import RunLogger
from lapwrench.hardware.log.live import ROBOT_DESCRIPTION_TOPIC, LiveError, urdf_with_assets
from lapwrench.hardware.log.topics import CYCLE_TOPIC, WRENCH_TOPIC
from lapwrench.robot.model import RobotModel

websockets = pytest.importorskip("websockets")
PROTOCOL = "foxglove.sdk.v1"


async def _session(port: int, logger: RunLogger, asset: str | None) -> dict[str, Any]:
    """Connect, read the advertised channels, subscribe to the robot description, log cycles until it
    arrives, and fetch ``asset``."""
    got: dict[str, Any] = {"topics": set(), "description": None, "asset": None}
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=[PROTOCOL], max_size=None) as ws:
        channels: dict[str, int] = {}
        deadline = time.monotonic() + 10.0
        k = 0
        subscribed = fetched = False
        while time.monotonic() < deadline and (got["description"] is None or (asset and got["asset"] is None)):
            logger.cycle(record(k))
            k += 1
            try:
                msg = await asyncio.wait_for(ws.recv(), 0.05)
            except TimeoutError:
                msg = None
            if isinstance(msg, str):
                op = json.loads(msg)
                if op["op"] == "advertise":
                    channels.update({c["topic"]: c["id"] for c in op["channels"]})
                    got["topics"] |= set(channels)
            elif isinstance(msg, bytes) and msg[0] == 0x01:  # message data: sub id, timestamp, payload
                got["description"] = json.loads(msg[1 + 4 + 8 :])
            elif isinstance(msg, bytes) and msg[0] == 0x04:  # fetch asset response
                _, status, n = struct.unpack_from("<IBI", msg, 1)
                got["asset"] = (status, msg[1 + 9 + n :])
            if not subscribed and ROBOT_DESCRIPTION_TOPIC in channels:
                sub = {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channels[ROBOT_DESCRIPTION_TOPIC]}]}
                await ws.send(json.dumps(sub))
                subscribed = True
            if asset and not fetched:
                await ws.send(json.dumps({"op": "fetchAsset", "uri": asset, "requestId": 7}))
                fetched = True
    return got


@pytest.fixture(scope="module")
def panda_model() -> RobotModel:
    return RobotModel("panda")


def test_a_live_run_advertises_the_log_channels_and_serves_the_urdf_and_its_meshes(panda_model: RobotModel) -> None:
    _, assets = urdf_with_assets(panda_model.urdf)
    mesh_uri, mesh_path = next(iter(assets.items()))
    logger = RunLogger(None, {"robot": "test"}, model=panda_model, live=("127.0.0.1", 0))
    try:
        assert logger.live is not None
        got = asyncio.run(_session(logger.live.address[1], logger, mesh_uri))
    finally:
        logger.close()
    assert {CYCLE_TOPIC, WRENCH_TOPIC, ROBOT_DESCRIPTION_TOPIC} <= got["topics"]
    description = got["description"]["data"]
    assert "<robot" in description and mesh_uri in description and str(mesh_path) not in description
    assert got["asset"] == (0, mesh_path.read_bytes())


def test_the_asset_handler_serves_only_the_meshes_of_the_urdf(panda_model: RobotModel, tmp_path: Path) -> None:
    secret = tmp_path / "secret.txt"
    secret.write_text("not for the network")
    logger = RunLogger(None, None, model=panda_model, live=("127.0.0.1", 0))
    try:
        assert logger.live is not None
        got = asyncio.run(_session(logger.live.address[1], logger, f"file://{secret}"))
    finally:
        logger.close()
    status, data = got["asset"]
    assert status == 1 and b"not for the network" not in data


def test_a_taken_port_is_one_line_and_leaves_a_valid_file(tmp_path: Path) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        with pytest.raises(LiveError, match=f"127.0.0.1:{port}.*in use") as err:
            RunLogger(tmp_path / "run.mcap", None, live=("127.0.0.1", port))
    assert "\n" not in str(err.value)
    assert (tmp_path / "run.mcap").read_bytes()[:8] == b"\x89MCAP0\r\n"


def test_a_logger_without_file_or_server_is_refused() -> None:
    with pytest.raises(ValueError, match="file, serves live telemetry, or both"):
        RunLogger(None)


def test_the_frame_tap_logs_the_newest_frame_at_5_hz_with_the_latest_detections(tmp_path: Path) -> None:
    import numpy as np

    from lapwrench.buffer import LatestValue
    from lapwrench.config import load
    from lapwrench.drivers.camera import CameraFrame
    from lapwrench.hardware.log import log_topics
    from lapwrench.hardware.log.live import FrameTap
    from lapwrench.hardware.log.topics import IMAGE_TOPIC

    frames: LatestValue[CameraFrame] = LatestValue("camera")
    path = tmp_path / "run.mcap"
    with RunLogger(path, None) as logger:
        logger.cycle(record(0))
        t0 = time.monotonic()
        tap = FrameTap(frames, logger, load(), t0)
        for i in range(12):  # 25 fps for ~0.5 s: the tap takes the newest every 0.2 s
            frames.put(CameraFrame(np.full((480, 640, 3), i, dtype=np.uint8), i))
            time.sleep(0.04)
        tap.close()
    n = log_topics(path)[IMAGE_TOPIC].messages
    assert 1 <= n <= 4


def test_the_live_view_draws_each_detection_and_ignores_non_finite_points() -> None:
    import numpy as np

    from lapwrench.config import load
    from lapwrench.hardware.log.live import annotated_view

    blank = np.zeros((480, 640, 3), dtype=np.uint8)
    img = annotated_view(blank, np.array([[100.0, 300.0], [np.nan, 5.0]]), load(), "handle")
    ring = img[294:307, 94:107]
    assert (ring[..., 1] > 200).any() and (ring[..., 0] < 50).all()  # a green mark at the detection
    assert not (annotated_view(blank, None, load(), "")[294:307, 94:107, 1] > 200).any()
