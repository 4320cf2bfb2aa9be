"""``lapwrench ui``'s arguments: a bad one is one line on stderr and exit code 2, before any simulation."""

from __future__ import annotations

import argparse
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
