"""lapwrench.hardware.log.live_sim: simulated runs streamed to a run logger (demo/ui --foxglove)."""

from __future__ import annotations

import asyncio
import base64
import itertools
import json
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from helpers import wait_until

from lapwrench.config import load
from lapwrench.hardware.log import RunLogger, read_log
from lapwrench.hardware.log.live_sim import SimTelemetry, live_simulation
from lapwrench.hardware.log.telemetry import simulation_layout
from lapwrench.hardware.log.topics import CYCLE_TOPIC
from lapwrench.sim.loop import ClosedLoop, observe_cycles
from lapwrench.sim.scripts import TISSUE_DEPTH


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
        loop = ClosedLoop(load(), detector="projected")  # draws no frames: the telemetry draws its own
        for _ in range(1000):  # 1 s
            loop.step(0.0)
    assert loop.camera is not None and not loop.camera.draws
    assert 4 <= log_topics(path)[IMAGE_TOPIC].messages <= 6


class _Images:
    """A run logger that keeps the images it is given."""

    def __init__(self) -> None:
        self.images: list[np.ndarray] = []

    def image(self, t: float, img: np.ndarray) -> None:
        self.images.append(img)


def test_the_telemetry_draws_the_frames_it_sends_when_the_loop_draws_none() -> None:
    logger = _Images()
    loop = ClosedLoop(load(), detector="projected")
    tel = SimTelemetry(logger)
    try:
        tel.frame(loop, np.zeros((0, 0, 3), np.uint8), 0.0)
        tel.frame(loop, np.zeros((0, 0, 3), np.uint8), 0.1)  # within 200 ms of the last: not sent
    finally:
        loop.close()
    cam = load().camera
    assert len(logger.images) == 1 and logger.images[0].shape == (cam.height, cam.width, 3)
    assert logger.images[0].std() > 1.0  # a drawn scene, not a blank


async def _cycle_messages(port: int, step: Callable[[], None], n: int) -> tuple[bytes, list[bytes]]:
    """Connect as Foxglove does, subscribe to the cycle channel and step the simulation until ``n``
    cycle messages arrived: (the channel's advertised schema, the messages' payloads)."""
    import websockets

    schema, payloads = b"", []
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], max_size=None) as ws:
        deadline = time.monotonic() + 60.0
        while time.monotonic() < deadline and len(payloads) < n:
            step()
            try:
                msg = await asyncio.wait_for(ws.recv(), 0.02)
            except TimeoutError:
                continue
            if isinstance(msg, str) and json.loads(msg)["op"] == "advertise" and not schema:
                channel = next((c for c in json.loads(msg)["channels"] if c["topic"] == CYCLE_TOPIC), None)
                if channel is not None:
                    schema = base64.b64decode(channel["schema"])
                    sub = {"op": "subscribe", "subscriptions": [{"id": 1, "channelId": channel["id"]}]}
                    await ws.send(json.dumps(sub))
            elif isinstance(msg, bytes) and msg[0] == 0x01:  # message data: sub id, timestamp, payload
                payloads.append(msg[1 + 4 + 8 :])
    return schema, payloads


def test_the_cues_telemetry_reaches_foxglove_live(capsys: pytest.CaptureFixture[str]) -> None:
    """``demo``/``ui --foxglove``: a loop with the zoom cue (added by type, as the zoom scenario does)
    observed through live_simulation; the cycle messages, decoded with the schema the server
    advertises, carry the zoom cue's spread, in_band and force."""
    pytest.importorskip("websockets")
    from google.protobuf import descriptor_pool
    from google.protobuf.descriptor_pb2 import FileDescriptorSet

    from lapwrench.hardware.log import decode_cycle
    from lapwrench.hardware.log.cycle_codec import CYCLE_SCHEMA_NAME, message_class

    cfg = load()
    layout = simulation_layout(cfg.cues)
    with live_simulation(("127.0.0.1", 0), cfg.robot.kind, "test", layout) as live:
        assert dict(live.logger.telemetry)["zoom"] == ("spread", "in_band", "force")
        loop = ClosedLoop(cfg.replace(cues={"zoom": {}}), detector="projected")
        centre = loop.world.incision_rest_position() + np.array([0.0, 0.0, -TISSUE_DEPTH])

        def step() -> None:  # ten cycles: SimTelemetry sends every tenth
            for _ in range(10):
                for i, side in enumerate((1.0, -1.0)):  # both instruments on the tissue, 4 cm apart
                    loop.world.set_instrument_tip(i, centre + np.array([0.0, 0.02 * side, 0.0]))
                loop.step(0.0)

        assert live.logger.live is not None
        schema, payloads = asyncio.run(_cycle_messages(live.logger.live.address[1], step, 15))
        loop.close()
    assert "live telemetry for Foxglove on ws://127.0.0.1:" in capsys.readouterr().err
    pool = descriptor_pool.DescriptorPool()
    for file in FileDescriptorSet.FromString(schema).file:
        pool.Add(file)
    cycle_class = message_class(pool.FindMessageTypeByName(CYCLE_SCHEMA_NAME))
    zoom = [decode_cycle(p, cycle_class)["telemetry"].get("zoom") for p in payloads]
    assert len(zoom) >= 15 and all(z is not None and set(z) == {"spread", "in_band", "force"} for z in zoom)
    seen = [z for z in zoom if z["spread"] is not None]  # the detector sees both instruments after a few frames
    assert seen and all(z["spread"] > 0 and z["in_band"] in (0.0, 1.0) and z["force"] is not None for z in seen)


def test_a_malformed_message_to_a_simulations_live_server_is_one_line_of_its_command(
        capfd: pytest.CaptureFixture[str]) -> None:
    """``demo --foxglove``: garbage from a Foxglove client is a line of ``lapwrench demo``, in lapwrench's
    words (foxglove-sdk's own record said 'Invalid message from ...', once per message, unlimited)."""
    websockets = pytest.importorskip("websockets")

    async def garbage(port: int) -> None:
        async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"]) as ws:
            await asyncio.wait_for(ws.recv(), 5.0)
            await ws.send("not json")
            await asyncio.sleep(0.3)

    with live_simulation(("127.0.0.1", 0), "panda", "lapwrench demo") as live:
        assert live.logger.live is not None
        asyncio.run(garbage(live.logger.live.address[1]))
        assert wait_until(lambda: live.logger.live is not None and live.logger.live.incidents.total == 1, 10)
    err = capfd.readouterr().err
    lines = [line for line in err.splitlines() if "malformed" in line]
    assert len(lines) == 1
    assert lines[0].startswith("lapwrench demo: Foxglove server: ignored a malformed message from 127.0.0.1:")
