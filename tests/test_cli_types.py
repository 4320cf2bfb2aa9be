"""The command line's argument types and output-path checks."""

from __future__ import annotations

import argparse
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from lapwrench import cli_types


# -- the argument types -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("parse", "good", "bad"),
    [
        (cli_types.positive_float, {"1": 1.0, "2.5e-3": 0.0025}, ["0", "-1", "nan", "inf", "-inf", "x", ""]),
        (cli_types.nonnegative_float, {"0": 0.0, "3": 3.0}, ["-1e-9", "nan", "inf"]),
        (cli_types.positive_int, {"1": 1, " 7 ": 7}, ["0", "-2", "1.5", "1e3", "9" * 5000, ""]),
        (cli_types.nonnegative_int, {"0": 0}, ["-1"]),
        (cli_types.int_in(0, 99), {"0": 0, "99": 99}, ["100", "-1"]),
        (cli_types.float_in(0.05, 1.0), {"0.05": 0.05, "1": 1.0}, ["0.04", "1.01", "nan"]),
        (cli_types.float_in(0.0, 1.0, lo_open=True), {"1e-9": 1e-9}, ["0", "-0.0"]),
        (cli_types.host_address, {"172.16.0.2": "172.16.0.2", "::1": "::1", "robot.local": "robot.local"},
         ["", "300.1.2.3", "1.2.3", "a b", "-bad-.lan", "x" * 300, "a..b"]),
        (cli_types.hex_bytes, {"AA55": b"\xaa\x55", "aa 55": b"\xaa\x55", "0xFF": b"\xff"},
         ["", "A", "ZZ", "0x", "00" * 9]),
        (cli_types.cpu_list, {"0": "0", "": ""}, ["a", "1,", "-1", "0;1", "100000"]),
        (cli_types.host_port,
         {"": ("127.0.0.1", 8765), ":0": ("127.0.0.1", 0), "0.0.0.0:9000": ("0.0.0.0", 9000),
          "ws.local": ("ws.local", 8765), "[::1]:81": ("::1", 81), "[::1]": ("::1", 8765)},
         ["1.2.3.4.5:9", ":70000", ":-1", ":x", "a b:1", "[::1", "[::1]x", "host:", "[::1]:"]),
    ],
)
def test_argument_types(parse: Callable[[str], Any], good: dict, bad: list[str]) -> None:
    for text, want in good.items():
        assert parse(text) == want
    for text in bad:
        with pytest.raises(argparse.ArgumentTypeError) as info:
            parse(text)
        assert len(str(info.value)) < 200


def test_output_path_checks_create_nothing(tmp_path: Path) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert cli_types.writable_file_problem(tmp_path / "new" / "deeper" / "log.mcap") is None
    assert cli_types.writable_dir_problem(tmp_path / "new" / "deeper") is None
    assert not (tmp_path / "new").exists()
    assert "not a folder" in (cli_types.writable_file_problem(blocker / "log.mcap") or "")
    assert "not a folder" in (cli_types.writable_dir_problem(blocker / "sub" / "dir") or "")
    assert "folder, not a file" in (cli_types.writable_file_problem(tmp_path) or "")
    assert "file, not a folder" in (cli_types.writable_dir_problem(blocker) or "")
    assert cli_types.writable_file_problem("") == "is empty"
    assert "NUL" in (cli_types.writable_file_problem("a\0b") or "")
    assert "not a usable path" in (cli_types.writable_file_problem(tmp_path / ("x" * 5000)) or "")
    assert sorted(tmp_path.iterdir()) == [blocker]  # the probes left nothing behind


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
def test_a_pseudo_filesystem_is_no_place_for_an_output_even_for_root() -> None:
    """Root passes every permission check, so ``os.access`` says /proc is writable; a probe file says
    it is not (before, ``run --log /proc/x.mcap`` failed with a traceback after the simulator started)."""
    assert "not writable" in (cli_types.writable_file_problem("/proc/x.mcap") or "")
    assert "not writable" in (cli_types.writable_dir_problem("/proc/run-out") or "")


def test_a_port_left_in_time_wait_by_the_last_sessions_clients_is_free_and_a_listening_one_is_not() -> None:
    """Ctrl-C on ``lapwrench ui`` with a page connected leaves its port in TIME_WAIT for up to a minute;
    the probe said "Address already in use" where the server itself would have started."""
    import socket

    server = socket.socket()
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as asyncio's and tokio's servers do
    server.bind(("127.0.0.1", 0))
    server.listen()
    port = server.getsockname()[1]
    assert cli_types.listen_problem("127.0.0.1", port) is not None  # listened on: taken
    client = socket.create_connection(("127.0.0.1", port))
    conn, _ = server.accept()
    conn.close()  # the server's side closes first: its port goes to TIME_WAIT
    client.recv(1)
    client.close()
    server.close()
    assert cli_types.listen_problem("127.0.0.1", port) is None
