"""``lapwrench run``'s argument checks before any device or robot (issue 11, items 8, 10 and 12) and the
tactile wire format chosen from the command line or the config."""

from __future__ import annotations

import argparse
import os
import socket
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lapwrench import config as config_mod
from lapwrench.drivers.tactile import ChecksumType, SerialTactileArray, TactileFrameFormat
from lapwrench.hardware import cli as hw
from lapwrench.hardware import franka
from lapwrench.hardware.devices import CliError, DryRunScript, _Devices, _open_sources, _TactileWriter, tactile_format


def parse(argv: list[str]) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    hw.add_run_arguments(p)
    return p.parse_args(argv)


def run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    code = hw.run_main(parse(argv))
    return code, capsys.readouterr().err


@pytest.fixture
def no_run(monkeypatch: pytest.MonkeyPatch) -> list[argparse.Namespace]:
    """Replace both run paths: what reaches them is recorded, nothing is started."""
    reached: list[argparse.Namespace] = []

    def fake(args: argparse.Namespace, cfg: Any) -> int:
        reached.append(args)
        return 0

    monkeypatch.setattr(hw, "_run_process", fake)
    monkeypatch.setattr(hw, "_run_in_process", fake)
    return reached


# -- item 12: an unreachable robot is named within seconds ---------------------------------------------
def test_probe_answers_for_a_listening_or_refusing_host() -> None:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as server:
        server.bind(("127.0.0.1", 0))
        server.listen(1)
        port = server.getsockname()[1]
        assert franka.probe_command_port("127.0.0.1", port, timeout=2.0) is None
    # nothing listens any more: refused, i.e. the host answered (libfranka reports that itself at once)
    assert franka.probe_command_port("127.0.0.1", port, timeout=2.0) is None


def test_probe_names_an_unknown_host() -> None:
    problem = franka.probe_command_port("no-such-robot.invalid", timeout=2.0)
    assert problem is not None and "no-such-robot.invalid" in problem


def test_the_probe_uses_libfrankas_command_port(monkeypatch: pytest.MonkeyPatch) -> None:
    seen: list[tuple[str, int]] = []

    def connect(address: tuple[str, int], timeout: float) -> Any:
        seen.append(address)
        raise TimeoutError("timed out")

    monkeypatch.setattr(franka.socket, "create_connection", connect)
    assert "no answer" in (franka.probe_command_port("172.16.0.2") or "")
    assert seen == [("172.16.0.2", 1337)] and franka.FRANKA_COMMAND_PORT == 1337


@pytest.mark.parametrize("error", [TimeoutError("timed out"), OSError(113, "No route to host")])
def test_run_names_an_unreachable_robot_at_once(
    error: OSError, monkeypatch: pytest.MonkeyPatch, no_run: list, capsys: pytest.CaptureFixture[str]
) -> None:
    """A robot that does not answer (a TEST-NET address: silence, or no route) is refused with one line
    naming it, before any device or the robot process; libfranka alone would wait 60 s in silence."""

    def silent(address: tuple[str, int], timeout: float) -> Any:
        assert timeout <= 5.0
        raise error

    monkeypatch.setattr(franka.socket, "create_connection", silent)
    code, err = run(["--robot-ip", "192.0.2.1", "--duration", "1"], capsys)
    assert code == 2 and not no_run
    assert err.count("\n") == 1 and "192.0.2.1" in err and "--robot-ip" in err


def test_the_dry_run_and_frankysim_probe_nothing(
    monkeypatch: pytest.MonkeyPatch, no_run: list, capsys: pytest.CaptureFixture[str]
) -> None:
    def never(*_a: Any, **_k: Any) -> Any:
        raise AssertionError("probed")

    monkeypatch.setattr(franka.socket, "create_connection", never)
    assert run(["--dry-run"], capsys)[0] == 0
    assert run(["--frankysim"], capsys)[0] == 0
    assert len(no_run) == 2


@pytest.mark.parametrize("bad", ["300.1.2.3", "", "robot ip", "-robot", "a" * 300])
def test_a_malformed_robot_address_is_an_argument_error(bad: str) -> None:
    with pytest.raises(SystemExit) as info:
        parse(["--robot-ip", bad])
    assert info.value.code == 2


# -- item 8: --detector without --camera -------------------------------------------------------------------
def test_a_detector_without_a_camera_is_refused(
    tmp_path: Path, no_run: list, capsys: pytest.CaptureFixture[str]
) -> None:
    model = tmp_path / "bad.onnx"
    model.write_bytes(b"garbage")
    code, err = run(["--dry-run", "--detector", str(model)], capsys)
    assert code == 2 and "--detector" in err and "--camera" in err and not no_run
    code, err = run(["--dry-run", "--camera", "v.avi", "--detector", str(tmp_path / "none.onnx")], capsys)
    assert code == 2 and "none.onnx" in err and "not found" in err
    assert run(["--dry-run"], capsys)[0] == 0 and no_run[-1].detector == "classical"  # the default
    assert run(["--dry-run", "--camera", "v.avi"], capsys)[0] == 0 and no_run[-1].detector == "classical"


def test_devices_a_dry_run_simulates_are_not_silently_ignored(
    no_run: list, capsys: pytest.CaptureFixture[str]
) -> None:
    for flag, value in (("--ft", "hex://192.168.1.1"), ("--tactile", "/dev/ttyUSB0"), ("--robot-ip", "10.0.0.2")):
        code, err = run(["--dry-run", flag, value], capsys)
        assert code == 2 and flag in err and "--dry-run" in err
    assert not no_run


def test_run_checks_the_log_path_and_the_ft_address_first(
    tmp_path: Path, no_run: list, capsys: pytest.CaptureFixture[str]
) -> None:
    blocker = tmp_path / "file"
    blocker.write_text("x")
    ns = parse(["--dry-run"])
    ns.log = str(blocker / "run.mcap")  # as a program calling run_main would pass it (no argparse type)
    assert hw.run_main(ns) == 2 and "--log" in capsys.readouterr().err
    code, err = run(["--robot-ip", "127.0.0.1", "--ft", "hex://[zz"], capsys)
    assert code == 2 and "--ft" in err
    code, err = run(["--robot-ip", "127.0.0.1", "--ft", "hex://127.0.0.1:0"], capsys)
    assert code == 2 and "port" in err
    assert not no_run


def test_the_argument_types_are_applied(tmp_path: Path) -> None:
    ns = parse(["--rt-cpus", " 0 ", "--tactile-header", "aa 55", "--max-rcm-error", "0.004", "--max-misses", "0"])
    assert ns.rt_cpus == "0" and ns.tactile_header == b"\xaa\x55" and ns.max_rcm_error == 0.004
    for argv in (["--duration", "nan"], ["--max-rcm-error", "-1"], ["--cycle-budget-us", "0"],
                 ["--camera-max-age", "0"], ["--log", str(tmp_path)], ["--rt-priority", "100"]):
        with pytest.raises(SystemExit) as info:
            parse(argv)
        assert info.value.code == 2


# -- the tactile wire format from the command line and the config ----------------------------------------------
def test_tactile_format_comes_from_the_config_and_the_options_override_it() -> None:
    cfg = config_mod.load()
    assert tactile_format(parse([]), cfg) == TactileFrameFormat()  # the packaged config: the driver default
    custom = cfg.replace(tactile={"header": "A5", "checksum": "sum8", "length_byte": True})
    fmt = tactile_format(parse([]), custom)
    assert (fmt.header, fmt.checksum, fmt.length_byte) == (b"\xa5", ChecksumType.SUM8, True)
    fmt = tactile_format(parse(["--tactile-checksum", "crc16-modbus", "--tactile-header", "55AA"]), custom)
    assert (fmt.header, fmt.checksum, fmt.length_byte) == (b"\x55\xaa", ChecksumType.CRC16_MODBUS, True)
    older = argparse.Namespace()  # a configuration object without the tactile section
    assert tactile_format(parse([]), older) == TactileFrameFormat()


def test_the_dry_run_tactile_array_speaks_the_chosen_format() -> None:
    """The simulated array writes, and the real reader reads, the format of the options (in-process path)."""
    cfg = config_mod.load()
    args = parse(["--dry-run", "--no-tare", "--tactile-checksum", "crc16-modbus", "--tactile-header", "C3"])
    args.tactile_frame_format = tactile_format(args, cfg)
    devices = _Devices()
    try:
        sources, described = _open_sources(args, cfg, devices, DryRunScript())
        assert sources.tactile is not None and "tactile" in described
    finally:
        devices.close()


def test_a_reader_of_another_format_gets_no_frame() -> None:
    """What the dry run would hit if the writer ignored the chosen format: no valid frame."""
    master, slave = os.openpty()
    writer = _TactileWriter(master, lambda: np.full(64, 7, np.uint8), fmt=TactileFrameFormat()).start()
    reader = SerialTactileArray(os.ttyname(slave), 115200, TactileFrameFormat(checksum="crc16-modbus"))
    try:
        reader.start()
        assert reader.buffer.wait_newer(0, timeout=0.5) is None
    finally:
        reader.stop()
        writer.stop()
        os.close(master)
        os.close(slave)


def test_a_tactile_config_the_driver_refuses_is_a_cli_error() -> None:
    class Section:
        header, checksum, length_byte, checksum_includes_header = "zz", "none", False, False

    cfg = argparse.Namespace(tactile=Section())
    with pytest.raises(CliError, match=r"tactile\.header"):
        tactile_format(parse([]), cfg)
