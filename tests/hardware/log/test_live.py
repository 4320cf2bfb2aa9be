"""lapwrench.hardware.log.live: the log's channels served to Foxglove over a WebSocket, checked with a
real WebSocket client speaking Foxglove's protocol (foxglove.sdk.v1)."""

from __future__ import annotations

import asyncio
import contextlib
import json
import socket
import struct
import time
from pathlib import Path
from typing import Any

import pytest
from hardware.log.support import record
from helpers import wait_until

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


def test_the_incident_log_prints_a_burst_per_window_on_one_line_each_and_counts_the_rest(
        capsys: pytest.CaptureFixture[str]) -> None:
    from lapwrench.hardware.log.live import INCIDENT_CHARS, IncidentLog

    now = [0.0]
    log = IncidentLog("lapwrench run", burst=3, window=10.0, clock=lambda: now[0])
    shown = [log.report(f"incident {i}") for i in range(5)]
    assert shown == [True, True, True, False, False]
    now[0] = 9.9  # the same window
    assert not log.report("incident 5")
    now[0] = 10.0
    assert log.report("a client's \x1b[2J garbage\nwith a newline " + "x" * 500)
    log.report("incident 7")
    log.report("incident 8")
    log.report("incident 9")  # held back
    log.close()
    lines = capsys.readouterr().err.splitlines()
    assert lines[:3] == [f"lapwrench run: incident {i}" for i in range(3)]
    assert lines[3].startswith("lapwrench run: a client's  [2J garbage with a newline xxx")
    suffix = " (and 3 more not shown)"
    assert lines[3].endswith(f"…{suffix}") and len(lines[3]) == INCIDENT_CHARS + len(suffix)
    assert lines[4:] == ["lapwrench run: incident 7", "lapwrench run: incident 8",
                         "lapwrench run: 1 more incidents from network clients not shown"]
    assert (log.total, log.printed, log.held_back) == (10, 6, 0)
    with pytest.raises(ValueError, match="at least one line"):
        IncidentLog("x", burst=0)


def _raw_client(port: int, data: bytes, reset: bool = False) -> None:
    """A TCP client that sends ``data`` and goes away (with a reset: mid-message)."""
    with socket.socket() as s:
        s.connect(("127.0.0.1", port))
        s.sendall(data)
        time.sleep(0.2)
        if reset:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))


async def _garbage(port: int, *frames: str | bytes, protocol: str = PROTOCOL) -> None:
    """A client that says hello and sends ``frames``, then waits for what the server answers."""
    try:
        async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=[protocol], max_size=None) as ws:
            await asyncio.wait_for(ws.recv(), 5.0)
            for frame in frames:
                await ws.send(frame)
            with contextlib.suppress(TimeoutError):
                while True:
                    await asyncio.wait_for(ws.recv(), 0.3)
    except (websockets.ConnectionClosed, websockets.InvalidHandshake):
        pass


async def _server_info(port: int) -> dict[str, Any]:
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=[PROTOCOL]) as ws:
        return dict(json.loads(await asyncio.wait_for(ws.recv(), 5.0)))


def test_garbage_sent_to_the_live_server_is_one_line_each_in_lapwrench_words_and_a_flood_one_burst(
        capfd: pytest.CaptureFixture[str]) -> None:
    """foxglove-sdk refuses the garbage and logs it in its words, one record each (printed as such by
    Python's last-resort handler, however many): here each is a line of the run's incident log, and a
    flood (the log's clock standing still) is one burst of lines and a count."""
    import logging

    from lapwrench.hardware.log.live import FOXGLOVE_LOG, INCIDENT_BURST

    with socket.socket() as s:  # a port nobody else uses, to tell foxglove's lines from others
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    logger = RunLogger(None, None, live=("127.0.0.1", port))
    try:
        assert logger.live is not None
        incidents = logger.live.incidents
        incidents.clock = lambda: 0.0
        steps: list[Any] = [
            lambda: asyncio.run(_garbage(port, "not json")),
            lambda: asyncio.run(_garbage(port, json.dumps({"op": "explode"}))),
            lambda: asyncio.run(_garbage(port, b"\xff\x00junk")),
            lambda: _raw_client(port, b"\x16\x03\x01 junk, not HTTP\r\n\r\n"),
            lambda: asyncio.run(_garbage(port, protocol="not-foxglove")),
        ]
        for k, step in enumerate(steps, 1):
            step()
            assert wait_until(lambda k=k: incidents.total >= k, 10)
        asyncio.run(_garbage(port, *["not json"] * 30))  # a flood
        assert wait_until(lambda: incidents.total >= len(steps) + 30, 10)
        assert asyncio.run(_server_info(port))["op"] == "serverInfo"
    finally:
        logger.close()
    assert FOXGLOVE_LOG not in logging.getLogger("foxglove").handlers
    err = capfd.readouterr().err
    lines = [line for line in err.splitlines() if line.startswith("lapwrench run: ")]
    assert len(lines) == INCIDENT_BURST + 1 and incidents.printed == INCIDENT_BURST
    prefix = "lapwrench run: Foxglove server: "
    assert lines[0].startswith(f"{prefix}ignored a malformed message from 127.0.0.1:")
    assert lines[1].startswith(f"{prefix}ignored a malformed message from 127.0.0.1:") and "explode" in lines[1]
    assert lines[2].startswith(f"{prefix}ignored a malformed message from 127.0.0.1:") and "opcode 255" in lines[2]
    assert lines[3].startswith(f"{prefix}refused a connection from 127.0.0.1:")
    assert lines[-1].endswith(" more incidents from network clients not shown")
    assert "Invalid message from" not in err and "Traceback" not in err
