"""MCAP round trip and report, the dry-run CLI, the Franka driver's conventions and errors, the runner
with stale sources."""

from __future__ import annotations

import argparse
import json
import socket
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hardware.support import FRANKYSIM_MISSING, build_loop

from lapwrench.buffer import LatestValue
from lapwrench.drivers.ft import Wrench
from lapwrench.hardware import cli as hw
from lapwrench.hardware.franka import CollisionThresholds, FrankaRobot, Payload, map_external_force
from lapwrench.hardware.log import CYCLE_TOPIC, EVENT_TOPIC, CycleRecord, RunLogger, iter_messages, read_log
from lapwrench.hardware.runner import Sources
from lapwrench.robot.description import ScopeGeometry
from lapwrench.robot.errors import RobotError
from lapwrench.robot_interface import RobotInterface
from lapwrench.sim.robot import ForceEstimateConfig, SimRobot


def record(k: int, **over: Any) -> CycleRecord:
    base = dict(
        t=k * 1e-3, robot_time=k * 1e-3, k=k, q=np.arange(7.0), dq=np.zeros(7), tau_J=np.ones(7),
        external_force=None, ft_force=np.array([1.0, 2.0, 3.0]), ft_torque=np.zeros(3), tactile=np.zeros(64),
        instruments=np.array([[10.0, 20.0]]), wrenches={"rcm": np.arange(6.0), "interaction": np.zeros(6)},
        mode="handle", delta=1.2, contacts=64, p_R=np.zeros(3), e_R=np.array([1e-3, 0, 0]), rcm_error=1e-3,
        rcm_error_measured=2e-3, q_ref=np.zeros(7), q_cmd=np.zeros(7), supervisor="running", alarm=False,
        compute_us=150.0, cycle_us=1000.0,
    )
    base.update(over)
    return CycleRecord(**base)


def test_mcap_round_trip_and_report(tmp_path: Path) -> None:
    path = tmp_path / "run.mcap"
    with RunLogger(path, {"robot": "test"}) as log:
        for k in range(200):
            log.cycle(record(k, ft_force=np.array([np.nan, 1.0, 2.0]) if k == 5 else np.array([1.0, 2.0, 3.0])))
        log.event(0.1, "rcm_error", "RCM error 12 mm; holding")
    cycles, events, meta = read_log(path)
    assert meta == {"robot": "test"}
    assert len(cycles) == 200 and [c["k"] for c in cycles] == list(range(200))
    assert cycles[3]["wrenches"]["rcm"] == list(range(6)) and cycles[3]["mode"] == "handle"
    assert cycles[5]["ft_force"] == [None, 1.0, 2.0]  # NaN survives as null, the file stays JSON
    assert cycles[0]["external_force"] is None
    assert events == [{"time": 0.1, "kind": "rcm_error", "message": "RCM error 12 mm; holding"}]
    topics = {t for t, _ in iter_messages(path)}
    assert {CYCLE_TOPIC, EVENT_TOPIC} <= topics
    # every channel has a schema Foxglove can show the fields with: JSON schemas for the JSON messages,
    # protobuf descriptors for the cycle and Foxglove's standard messages (tests/hardware/test_log.py)
    from mcap.reader import make_reader

    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    schemas = {ch.topic: (summary.schemas[ch.schema_id], ch.message_encoding) for ch in summary.channels.values()}
    assert {(schema.encoding, encoding) for schema, encoding in schemas.values()} == {
        ("jsonschema", "json"),
        ("protobuf", "protobuf"),
    }
    assert schemas[CYCLE_TOPIC][0].name == "lapwrench.Cycle"
    out = tmp_path / "report"
    assert hw.log_report_main(argparse.Namespace(log=str(path), out=str(out))) == 0
    for name in ("rcm_error.png", "wrenches.png", "mode.png", "joint_commands.png"):
        assert (out / name).stat().st_size > 5000
    assert hw.log_report_main(argparse.Namespace(log=str(tmp_path / "none.mcap"), out=str(out))) == 2


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


def test_external_force_sign_mapping() -> None:
    # libfranka: forces the robot applies to the environment are positive
    assert np.allclose(map_external_force([1, 2, 3, 9, 9, 9], "robot_on_environment"), [-1, -2, -3])
    assert np.allclose(map_external_force([1, 2, 3, 9, 9, 9], "environment_on_robot"), [1, 2, 3])
    with pytest.raises(ValueError):
        FrankaRobot("127.0.0.1", ext_wrench_sign="up")  # type: ignore[arg-type]
    with pytest.raises(ValueError):
        CollisionThresholds(lower_torque=(50.0,) * 7)


def test_scope_payload() -> None:
    p = Payload.from_scope(ScopeGeometry())
    assert p.mass == pytest.approx(0.8)
    assert 0.04 < p.com[2] < 0.145 and p.inertia[0] > 0 and p.inertia[8] > 0


@pytest.mark.skipif(FRANKYSIM_MISSING is not None, reason=f"pylibfranka unusable: {FRANKYSIM_MISSING}")
def test_unreachable_robot_error_names_the_address() -> None:
    s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    try:
        s.bind(("127.0.0.1", 1337))
    except OSError:
        pytest.skip("127.0.0.1:1337 is in use (a franky-sim server is running)")
    finally:
        s.close()
    robot = FrankaRobot("127.0.0.1", kind="fr3", realtime="ignore")
    assert isinstance(robot, RobotInterface)
    with pytest.raises(RobotError, match=r"127\.0\.0\.1"):
        robot.connect()
    with pytest.raises(RobotError, match="not connected"):
        robot.read()


def test_sim_robot_estimates_the_hand_force_from_joint_torques(sim_world: Any) -> None:
    robot = SimRobot(sim_world, hand_force_H=lambda t: np.array([5.0, 0.0, 0.0]) if t > 0.1 else np.zeros(3))
    assert isinstance(robot, RobotInterface)
    r = robot.connect()
    assert np.linalg.norm(r.external_force) < 0.5
    for _ in range(400):
        r = robot.read()
        robot.command(r.q * 0 + sim_world.q_ref)
    truth = sim_world.hand_force() + sim_world.contact_force()
    assert np.linalg.norm(r.external_force - truth) < 0.5
    biased = SimRobot(sim_world, estimate=ForceEstimateConfig(torque_bias=0.5, torque_noise=0.05, seed=1))
    r2 = biased.connect()
    assert np.linalg.norm(r2.external_force - truth) > 0.1  # a torque bias shows up as a force


def test_runner_with_stale_sources_never_waits(sim_world: Any, panda_cfg: Any) -> None:
    ft: LatestValue[Any] = LatestValue("ft")
    ft.put(Wrench(np.array([5.0, 0, 0]), np.zeros(3)), time.monotonic() - 10.0)  # long stale
    tactile: LatestValue[Any] = LatestValue("tactile")  # never published
    loop, log = build_loop(SimRobot(sim_world), panda_cfg, None)
    loop.sources = Sources(ft=ft, tactile=tactile)
    stats = loop.run(0.5)
    assert stats.cycles >= 500 and stats.alarm is None
    assert all(c.ft_force is None and c.tactile is None for c in log.cycles)
    stale = [m for _, k, m in log.events if k == "input_stale"]
    assert any(m.startswith("ft") for m in stale) and any(m.startswith("tactile") for m in stale)
    assert np.percentile(stats.compute_us, 50) < 5000


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
