"""``lapwrench run``: argument checks before any device or robot (issue 11, items 8, 10 and 12), the
dry-run smoke run, device specs, and the refused control rates."""

from __future__ import annotations

import argparse
import json
import socket
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from lapwrench.hardware import cli as hw
from lapwrench.hardware import franka
from lapwrench.hardware.log import read_log


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

    monkeypatch.setattr(hw, "run_process", fake)
    monkeypatch.setattr(hw, "run_in_process", fake)
    return reached


def run_args(**kw: Any) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    hw.add_run_arguments(p)
    argv = []
    for k, v in kw.items():
        flag = "--" + k.replace("_", "-")
        argv += [flag] if v is True else [flag, str(v)]
    return p.parse_args(argv)


def test_dry_run_cli_smoke(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log = tmp_path / "dry.mcap"
    code = hw.run_main(run_args(dry_run=True, duration=2.5, log=log, max_misses=0))
    out = capsys.readouterr()
    assert code == 0, out
    summary = json.loads(out.out.strip().splitlines()[-1])
    assert summary["cycles"] >= 2500 and summary["stopped_at_rest"] and summary["alarm"] is None
    assert "OnRobot HEX sensor at udp://127.0.0.1" in out.err and "tactile array on serial port" in out.err
    cycles, events, meta = read_log(log)
    assert meta["dry_run"] is True and len(cycles) >= 2500
    assert any(c["mode"] == "handle" for c in cycles)  # the scripted grip + push reached the controller
    assert any(e["kind"] == "start" for e in events)


def test_run_names_the_missing_device_before_the_robot(capsys: pytest.CaptureFixture[str]) -> None:
    code = hw.run_main(run_args(robot_ip="127.0.0.1", tactile="/dev/lapwrench-no-such-port", duration=1))
    err = capsys.readouterr().err
    assert code == 2 and "/dev/lapwrench-no-such-port" in err
    # an F/T box that does not answer (a free loopback UDP port): named, with a timeout
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    code = hw.run_main(run_args(robot_ip="127.0.0.1", ft=f"hex://127.0.0.1:{port}", duration=1))
    err = capsys.readouterr().err
    assert code == 2 and f"udp://127.0.0.1:{port}" in err
    assert hw.run_main(run_args(ft="bogus://x")) == 2  # no --robot-ip and no --dry-run


def test_run_refuses_a_camera_whose_frames_do_not_match_the_intrinsics(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import cv2

    video = tmp_path / "scope_320x240.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 25.0, (320, 240))
    for _ in range(5):
        writer.write(np.full((240, 320, 3), 90, np.uint8))
    writer.release()
    code = hw.run_main(run_args(robot_ip="127.0.0.1", camera=str(video), duration=1))
    err = capsys.readouterr().err
    # the packaged intrinsics are for 640x480 frames: named before the robot is contacted
    assert code == 2 and "scope_320x240.avi" in err and "640x480" in err, err


def test_parse_device_specs() -> None:
    assert hw.parse_ft_url("hex://192.168.1.1") == ("hex", "192.168.1.1", 49152)
    assert hw.parse_ft_url("ati://10.0.0.5:5000") == ("ati", "10.0.0.5", 5000)
    with pytest.raises(hw.CliError):
        hw.parse_ft_url("http://x")
    assert hw.parse_camera("0") == 0 and hw.parse_camera("video.mp4") == "video.mp4"


@pytest.mark.parametrize("rate", [500, 250, 2000])
def test_run_refuses_a_control_rate_the_franka_does_not_run_at(
    tmp_path: Path, rate: int, capsys: pytest.CaptureFixture[str]
) -> None:
    """The Franka differentiates every command over 1 ms: any other configured rate would let the
    shaper and the supervisor work with a wrong period (issue 11, item 1)."""
    cfg = tmp_path / "rate.yaml"
    cfg.write_text(f"robot: {{control_rate_hz: {rate}}}\n")
    code = hw.run_main(run_args(dry_run=True, config=str(cfg), duration=1))
    err = capsys.readouterr().err
    assert code == 2 and "control_rate_hz must be 1000" in err


def test_run_refuses_the_printed_euler_step_with_the_printed_damping_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Refused before the loop's process starts (there it was a 'robot error' with a traceback)."""
    cfg = tmp_path / "explicit.yaml"
    cfg.write_text("motion: {integrator: explicit}\n")
    code = hw.run_main(run_args(dry_run=True, config=str(cfg), duration=1))
    err = capsys.readouterr().err
    assert code == 2 and "motion.integrator: explicit" in err and "Traceback" not in err and len(err.splitlines()) == 1


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


def test_run_refuses_a_cue_that_needs_an_input_the_robot_path_has_no_source_for(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], no_run: list
) -> None:
    from fake_plugins import install

    install(monkeypatch)
    cfg = tmp_path / "pedal.yaml"
    cfg.write_text("cues:\n  pedal_hold: {}\n")
    code = hw.run_main(run_args(dry_run=True, config=str(cfg), duration=1))
    err = capsys.readouterr().err
    assert code == 2 and "cue 'pedal_hold' needs input 'pedal'" in err and err.count("\n") == 1 and not no_run


def test_run_refuses_a_foxglove_port_in_use_before_the_robot_moves(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        code = hw.run_main(run_args(dry_run=True, duration=1, foxglove=f"127.0.0.1:{port}", in_process=True))
    err = capsys.readouterr().err
    assert code == 2 and f"--foxglove cannot listen on 127.0.0.1:{port}" in err and "in use" in err


def test_foxglove_takes_an_optional_address() -> None:
    assert run_args(foxglove=True).foxglove == ("127.0.0.1", 8765)
    assert run_args(foxglove=":0").foxglove == ("127.0.0.1", 0)
    assert run_args().foxglove is None
