"""lapwrench.ui.untrusted: what a hostile client sends the page's viser server is one line on stderr
(rate-limited), never a library's traceback; the server serves a well-behaved client afterwards; and a
failure of lapwrench's own code on viser's loop still shows its traceback.

The server is viser's, on a free port, with :class:`UntrustedClients` installed as
:class:`~lapwrench.ui.app.UiApp` installs it; the clients are raw WebSocket (and TCP) clients. Under
pytest the libraries' log records go to pytest's handlers, not to stderr: the tests read them with
``caplog`` (a traceback is a record with ``exc_info``) and read our lines with ``capfd``.
"""

from __future__ import annotations

import asyncio
import logging
import socket
import time
from collections.abc import Iterator
from typing import Any

import pytest
from helpers import wait_until

from lapwrench.hardware.log.live import INCIDENT_BURST, IncidentLog
from lapwrench.ui.inputs import UiInputError, checked_number
from lapwrench.ui.untrusted import PageServer, UntrustedClients

viser = pytest.importorskip("viser")
websockets = pytest.importorskip("websockets")
msgspec = pytest.importorskip("msgspec")
PROTOCOL = f"viser-v{viser.__version__}"
WHO = "lapwrench ui: "
LABEL = "push (N)"


class Page:
    """The page's viser server with one slider, its hostile clients guarded against (as UiApp builds it)."""

    def __init__(self, clock: Any = time.monotonic) -> None:
        self.server = PageServer(host="127.0.0.1", port=0, verbose=False)
        self.slider = self.server.gui.add_slider(LABEL, 0.0, 30.0, 0.5, 0.0)
        self.untrusted = UntrustedClients(self.server, IncidentLog("lapwrench ui", clock=clock))
        self.port = int(self.server.get_port())

    def stop(self) -> None:
        self.server.stop()
        self.untrusted.close()


@pytest.fixture
def page() -> Iterator[Page]:
    p = Page()
    try:
        yield p
    finally:
        p.stop()


def tracebacks(caplog: pytest.LogCaptureFixture) -> list[BaseException | None]:
    """The exceptions of the log records that carry a traceback (printed, without a logging set-up)."""
    return [r.exc_info[1] for r in caplog.records if r.exc_info]


def update(uuid: str, **updates: object) -> bytes:
    """A page's update of a GUI element, as it goes on the wire."""
    return msgspec.msgpack.encode({"type": "GuiUpdateMessage", "uuid": uuid, "updates": updates})


def our_lines(err: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith(WHO)]


async def serves(port: int) -> bool:
    """A well-behaved client connects and gets the scene and the page's elements."""
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=[PROTOCOL], max_size=None) as ws:
        frame = await asyncio.wait_for(ws.recv(), 10.0)
    return isinstance(frame, bytes) and len(frame) > 16


async def slider_uuid(ws: Any) -> str:
    """The slider's id, found by its label in what the server sends a page (as the page finds it)."""
    import zstandard

    while True:
        raw = await asyncio.wait_for(ws.recv(), 10.0)
        n = int.from_bytes(raw[8:16], "little")
        for m in msgspec.msgpack.decode(zstandard.ZstdDecompressor().decompress(raw[16:16 + n]))["messages"]:
            if m["type"].startswith("Gui") and isinstance(m.get("props"), dict) and m["props"].get("label") == LABEL:
                return str(m["uuid"])


async def send_and_wait_for_close(port: int, payload: str | bytes) -> bool:
    """Send ``payload``; True if the server then closed the connection."""
    async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=[PROTOCOL], max_size=None) as ws:
        await ws.send(payload)
        try:
            while True:
                await asyncio.wait_for(ws.recv(), 10.0)
        except websockets.ConnectionClosed:
            return True
        except TimeoutError:
            return False


CAMERA = {  # a page's hello: viser counts a client as connected from its first camera pose
    "type": "ViewerCameraMessage", "wxyz": [1.0, 0, 0, 0], "position": [1.0, 0, 0], "fov": 1.0, "near": 0.01,
    "far": 10.0, "image_height": 480, "image_width": 640, "look_at": [0.0, 0, 0], "up_direction": [0.0, 0, 1]}

GARBAGE: dict[str, str | bytes] = {
    "a text frame": "hello, not msgpack",
    "bytes that are not msgpack": b"\xc1\xff\x00garbage",
    "msgpack that is not a map": msgspec.msgpack.encode(5),
    "a map without a type": msgspec.msgpack.encode({"foo": 1}),
    "a type that is not a string": msgspec.msgpack.encode({"type": [1, 2]}),
    "an unknown type": msgspec.msgpack.encode({"type": "NoSuchMessage"}),
    "a message without its fields": msgspec.msgpack.encode({"type": "ViewerCameraMessage"}),
    "fields of the wrong type": msgspec.msgpack.encode({
        "type": "ViewerCameraMessage", "wxyz": "abcd", "position": [1, 2], "fov": "x", "near": None, "far": [],
        "image_height": "h", "image_width": -1, "look_at": 3, "up_direction": {}}),
}


@pytest.mark.parametrize("payload", GARBAGE.values(), ids=GARBAGE.keys())
def test_garbage_that_viser_cannot_decode_closes_that_connection_with_one_line(
        page: Page, payload: str | bytes, caplog: pytest.LogCaptureFixture, capfd: pytest.CaptureFixture[str]) -> None:
    """Without the guard: websockets' 'connection handler failed' and the traceback of viser's decoder."""
    assert asyncio.run(send_and_wait_for_close(page.port, payload))
    assert wait_until(lambda: page.untrusted.incidents.total == 1, 10)
    assert asyncio.run(serves(page.port))
    err = capfd.readouterr().err
    lines = our_lines(err)
    assert len(lines) == 1 and lines[0].startswith(f"{WHO}closed the connection of 127.0.0.1:")
    assert "after a malformed message: " in lines[0]
    assert "Traceback" not in err and not tracebacks(caplog)


def test_a_message_viser_cannot_apply_is_one_line_and_the_page_stays_connected(
        page: Page, caplog: pytest.LogCaptureFixture, capfd: pytest.CaptureFixture[str]) -> None:
    """A slider set to a string, a property it does not have: without the guard, asyncio's 'Task
    exception was never retrieved' and viser's traceback, for each message."""
    async def session() -> None:
        async with websockets.connect(f"ws://127.0.0.1:{page.port}", subprotocols=[PROTOCOL], max_size=None) as ws:
            uuid = await slider_uuid(ws)
            for bad in (update(uuid, value="not a number"), update(uuid, no_such_property=1), update(uuid, value={})):
                await ws.send(bad)
            await ws.send(update(uuid, value=12.5))
            end = time.monotonic() + 10.0
            while page.slider.value != 12.5 and time.monotonic() < end:  # the same page, still heard
                await asyncio.sleep(0.02)

    asyncio.run(session())
    assert page.slider.value == 12.5
    assert wait_until(lambda: page.untrusted.incidents.total == 3, 10)
    err = capfd.readouterr().err
    lines = our_lines(err)
    assert len(lines) == 3
    assert all(line.startswith(f"{WHO}ignored a malformed message from page client ") for line in lines)
    assert "GuiUpdateMessage: ValueError: could not convert string to float: 'not a number'" in lines[0]
    assert "Traceback" not in err and not tracebacks(caplog)


def test_a_flood_of_garbage_prints_one_burst_per_window_and_counts_the_rest(
        caplog: pytest.LogCaptureFixture, capfd: pytest.CaptureFixture[str]) -> None:
    """Sixty malformed messages while the incident log's clock stands still: the first burst is printed,
    the rest are counted, and the end of the server says how many were not shown."""
    page = Page(clock=lambda: 0.0)
    try:
        async def flood() -> None:
            async with websockets.connect(f"ws://127.0.0.1:{page.port}", subprotocols=[PROTOCOL]) as ws:
                bad = update(await slider_uuid(ws), value="x")
                for _ in range(60):
                    await ws.send(bad)
                await asyncio.sleep(0.1)

        asyncio.run(flood())
        assert wait_until(lambda: page.untrusted.incidents.total == 60, 10)
        assert asyncio.run(serves(page.port))
    finally:
        page.stop()
    err = capfd.readouterr().err
    lines = our_lines(err)
    assert len(lines) == INCIDENT_BURST + 1 and page.untrusted.incidents.printed == INCIDENT_BURST
    assert lines[-1] == f"{WHO}{60 - INCIDENT_BURST} more incidents from network clients not shown"
    assert "Traceback" not in err and not tracebacks(caplog)


def _raw(port: int, data: bytes, reset: bool = False) -> None:
    """A TCP client that sends ``data`` and goes away (with a reset: mid-message)."""
    with socket.create_connection(("127.0.0.1", port)) as s:
        s.sendall(data)
        time.sleep(0.2)
        if reset:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, b"\x01\x00\x00\x00\x00\x00\x00\x00")


def _handshake(port: int) -> bytes:
    return (f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n"
            f"Sec-WebSocket-Protocol: {PROTOCOL}\r\n\r\n").encode()


def test_junk_instead_of_a_handshake_is_one_line_even_as_the_first_connection(
        page: Page, caplog: pytest.LogCaptureFixture, capfd: pytest.CaptureFixture[str]) -> None:
    """The first connection to a fresh server is not HTTP (without the guard: 'opening handshake failed'
    and its traceback; viser hides it only after its first HTTP request). A client that hangs up
    mid-request, a bad upgrade, a frame cut off by a reset, a protocol violation: nothing to tell, or one
    line each; never a traceback."""
    _raw(page.port, b"\x16\x03\x01 junk, not HTTP\r\n\r\n")
    assert wait_until(lambda: page.untrusted.incidents.total == 1, 10)
    _raw(page.port, b"GET / HTTP/1.1\r\nHost: x", reset=True)  # hung up mid-request: not an incident
    _raw(page.port, b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n\r\n")
    _raw(page.port, _handshake(page.port) + b"\x82\xfe\x10\x00\x11\x22\x33\x44" + b"x" * 100, reset=True)
    _raw(page.port, _handshake(page.port) + b"\x8f\x05hello")  # a reserved opcode, unmasked
    assert asyncio.run(serves(page.port))
    err = capfd.readouterr().err
    lines = our_lines(err)
    assert lines and lines[0].startswith(f"{WHO}refused a connection from 127.0.0.1:")
    assert "did not receive a valid HTTP request" in lines[0]
    assert len(lines) <= 2  # the junk, and at most the bad upgrade
    assert "Traceback" not in err and not tracebacks(caplog)


def test_a_clients_garbage_is_one_line_but_a_failure_of_lapwrench_code_still_shows_its_traceback(
        page: Page, caplog: pytest.LogCaptureFixture, capfd: pytest.CaptureFixture[str]) -> None:
    """An update callback of ours that raises on viser's event loop is a bug of ours, not a client's
    garbage: asyncio's traceback stays for it, while the garbage next to it is one line."""
    async def strict(event: Any) -> None:
        checked_number(float("nan"), "push (N)", 0.0, 30.0)  # raises UiInputError, in lapwrench's code

    page.slider.on_update(strict)

    async def session() -> None:
        async with websockets.connect(f"ws://127.0.0.1:{page.port}", subprotocols=[PROTOCOL]) as ws:
            await ws.send(msgspec.msgpack.encode(CAMERA))  # viser calls callbacks for pages it counts connected
            uuid = await slider_uuid(ws)
            await ws.send(update(uuid, value="garbage"))
            await ws.send(update(uuid, value=3.0))
            await asyncio.sleep(0.3)

    with caplog.at_level(logging.ERROR):
        asyncio.run(session())
        assert wait_until(lambda: any(isinstance(e, UiInputError) for e in tracebacks(caplog)), 10)
        assert wait_until(lambda: page.untrusted.incidents.total == 1, 10)
    assert [e for e in tracebacks(caplog) if not isinstance(e, UiInputError)] == []
    lines = our_lines(capfd.readouterr().err)
    assert len(lines) == 1 and "could not convert string to float: 'garbage'" in lines[0]


def test_a_request_to_share_the_page_on_the_internet_is_refused_with_one_line(
        page: Page, caplog: pytest.LogCaptureFixture, capfd: pytest.CaptureFixture[str]) -> None:
    """viser opens a public tunnel (share.viser.studio) for any client's ShareUrlRequest, e.g. a web page in
    the user's browser that opens a WebSocket to localhost: the page's server refuses it, and says so."""
    async def ask() -> None:
        async with websockets.connect(f"ws://127.0.0.1:{page.port}", subprotocols=[PROTOCOL], max_size=None) as ws:
            await ws.send(msgspec.msgpack.encode({"type": "ShareUrlRequest"}))
            await asyncio.sleep(0.2)

    asyncio.run(ask())
    assert wait_until(lambda: page.untrusted.incidents.total == 1, 10)
    assert page.server.request_share_url() is None  # nothing to share, whoever asks
    err = capfd.readouterr().err
    lines = our_lines(err)
    assert lines[0] == f"{WHO}refused a request to share the page on the internet (lapwrench never shares it)"
    assert "Traceback" not in err and not tracebacks(caplog)
