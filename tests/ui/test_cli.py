"""``lapwrench ui``'s arguments: a bad one is one line on stderr and exit code 2, before any simulation."""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import socket
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from lapwrench.cli_types import ArgumentParser
from lapwrench.ui.cli import UiUsageError, add_ui_parser, check_address, main, ui_main


def parse(argv: list[str]) -> argparse.Namespace:
    p = ArgumentParser(prog="lapwrench")
    add_ui_parser(p.add_subparsers(dest="command", required=True))
    return p.parse_args(["ui", *argv])


@pytest.fixture
def busy_port() -> Iterator[int]:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield s.getsockname()[1]


def test_the_ui_command_has_its_defaults_and_entry() -> None:
    args = parse([])
    assert (args.host, args.port, args.seed, args.detector, args.view_fps) == ("127.0.0.1", 8080, 0, "projected", 25.0)
    assert args.func is ui_main


@pytest.mark.parametrize("argv", [["--port", "70000"], ["--host", "bad host!"], ["--detector", "magic"],
                                  ["--view-fps", "nan"], ["--seed", "-1"]])
def test_argparse_refuses_bad_values(argv: list[str], capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines[0].startswith("usage: lapwrench ui")
    assert lines[-1].startswith("lapwrench ui: error: argument --")  # argparse's usage, then one error line


def test_a_port_in_use_is_one_line_and_exit_2(busy_port: int, capsys: pytest.CaptureFixture[str]) -> None:
    assert ui_main(parse(["--port", str(busy_port)])) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("lapwrench ui: ") and "in use" in err and len(err.splitlines()) == 1


def test_an_address_not_on_this_machine_is_refused() -> None:
    with pytest.raises(UiUsageError, match="cannot"):
        check_address("192.0.2.1", 0)  # TEST-NET-1: never a local address
    with pytest.raises(UiUsageError, match="resolve"):
        check_address("no-such-host.invalid", 0)


def test_a_bad_config_is_one_line_and_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("tracking:\n  epsilon1: 300\n")
    assert ui_main(parse(["--config", str(bad), "--port", "0"])) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("lapwrench ui: --config") and "epsilon2" in err and len(err.splitlines()) == 1
    assert ui_main(parse(["--config", str(tmp_path / "missing.yaml"), "--port", "0"])) == 2


def test_a_port_taken_after_the_check_is_one_line_and_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    """The page's port taken between the check and the start (here by the Foxglove server of the same
    run): viser moved to the next free port silently ('serving http://127.0.0.1:8766'), so the page was
    not where it was asked to be."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    # were the page served anyway, it would run until stopped: stop it as Ctrl-C would
    stopper = threading.Timer(60.0, os.kill, (os.getpid(), signal.SIGINT))
    stopper.start()
    try:
        code = ui_main(parse(["--port", str(port), "--foxglove", f"127.0.0.1:{port}"]))
    finally:
        stopper.cancel()
    out, err = capsys.readouterr()
    assert code == 2 and "serving" not in out
    last = err.strip().splitlines()[-1]
    assert last.startswith(f"lapwrench ui: --host/--port 127.0.0.1:{port}: ") and "in use" in last


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


async def _hostile_clients(page: int, fox: int) -> None:
    """What a hostile raw client sends each server of ``lapwrench ui --foxglove``: a text frame, bytes
    that are not msgpack, a slider set to a string, a tuple of the wrong length, junk instead of a
    handshake (the page, viser); garbage JSON and binary junk (Foxglove)."""
    import asyncio

    import msgspec
    import viser
    import websockets
    import zstandard

    protocol = f"viser-v{viser.__version__}"
    for frame in ("hello", b"\xc1\xff\x00garbage"):
        async with websockets.connect(f"ws://127.0.0.1:{page}", subprotocols=[protocol], max_size=None) as ws:
            await ws.send(frame)
            with contextlib.suppress(websockets.ConnectionClosed):
                while True:
                    await asyncio.wait_for(ws.recv(), 30.0)
    async with websockets.connect(f"ws://127.0.0.1:{page}", subprotocols=[protocol], max_size=None) as ws:
        uuid = None
        while uuid is None:  # the slider, found by its label as the page finds it
            raw = await asyncio.wait_for(ws.recv(), 30.0)
            n = int.from_bytes(raw[8:16], "little")
            for m in msgspec.msgpack.decode(zstandard.ZstdDecompressor().decompress(raw[16:16 + n]))["messages"]:
                if isinstance(m.get("props"), dict) and m["props"].get("label") == "push (N)":
                    uuid = m["uuid"]
        await ws.send(msgspec.msgpack.encode({"type": "GuiUpdateMessage", "uuid": uuid, "updates": {"value": "x"}}))
        await ws.send(msgspec.msgpack.encode({
            "type": "ViewerCameraMessage", "wxyz": [1.0, 0, 0, 0], "position": [1.0, 0], "fov": 1.0, "near": 0.01,
            "far": 10.0, "image_height": 480, "image_width": 640, "look_at": [0.0, 0, 0], "up_direction": [0.0, 0, 1]}))
        await asyncio.sleep(1.0)
    with socket.create_connection(("127.0.0.1", page)) as s:
        s.sendall(b"\x16\x03\x01 junk, not HTTP\r\n\r\n")
        s.recv(1024)
    async with websockets.connect(f"ws://127.0.0.1:{fox}", subprotocols=["foxglove.sdk.v1"]) as ws:
        await asyncio.wait_for(ws.recv(), 30.0)
        for junk in ("not json", b"\xff\x00junk"):
            await ws.send(junk)
        await asyncio.sleep(1.0)


async def _well_behaved_clients(page: int, fox: int) -> tuple[bool, str]:
    """A page's client gets the scene; a Foxglove client gets the server's info."""
    import asyncio
    import json

    import viser
    import websockets

    async with websockets.connect(f"ws://127.0.0.1:{page}", subprotocols=[f"viser-v{viser.__version__}"],
                                  max_size=None) as ws:
        scene = await asyncio.wait_for(ws.recv(), 30.0)
    async with websockets.connect(f"ws://127.0.0.1:{fox}", subprotocols=["foxglove.sdk.v1"]) as ws:
        info = json.loads(await asyncio.wait_for(ws.recv(), 30.0))
    return isinstance(scene, bytes) and len(scene) > 16, info["op"]


@pytest.mark.slow
def test_hostile_clients_of_the_page_and_of_foxglove_are_one_line_each_and_both_serve_on(tmp_path: Path) -> None:
    """``lapwrench ui --foxglove`` as run from a shell, its stderr as the operator sees it: each piece of
    garbage is one ``lapwrench ui: ...`` line; no traceback (there was one per message, from websockets,
    asyncio or viser) and no warning; both servers serve well-behaved clients afterwards; Ctrl-C ends it."""
    import asyncio
    import subprocess
    import sys
    import time

    pytest.importorskip("websockets")
    page, fox = _free_port(), _free_port()
    out, err = tmp_path / "stdout", tmp_path / "stderr"
    cmd = [sys.executable, "-m", "lapwrench.cli", "ui", "--port", str(page), "--foxglove", f"127.0.0.1:{fox}",
           "--view-fps", "2"]
    with out.open("wb") as o, err.open("wb") as e:
        proc = subprocess.Popen(cmd, env={**os.environ, "MUJOCO_GL": "egl"}, stdout=o, stderr=e,
                                start_new_session=True)
    try:
        deadline = time.monotonic() + 300.0
        while "serving" not in out.read_text() and time.monotonic() < deadline:
            assert proc.poll() is None, err.read_text()
            time.sleep(0.2)
        asyncio.run(_hostile_clients(page, fox))
        assert asyncio.run(_well_behaved_clients(page, fox)) == (True, "serverInfo")
        proc.send_signal(signal.SIGINT)
        assert proc.wait(120) == 0
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    text = err.read_text()
    assert "Traceback" not in text and "Task exception" not in text and "does not match annotation" not in text, text
    lines = text.splitlines()
    assert all(line.startswith("lapwrench ui: ") for line in lines if "127.0.0.1" in line or "client" in line), text
    for said in ("closed the connection of 127.0.0.1:", "ignored a malformed message from page client ",
                 "refused a connection from 127.0.0.1:",
                 "Foxglove server: ignored a malformed message from 127.0.0.1:"):
        assert any(said in line for line in lines), (said, text)
