"""lapwrench.hardware.grip_identify: ``lapwrench identify-grip`` fits the grip from a run's log."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from hardware.log.support import record

from lapwrench import config as config_mod
from lapwrench.cli import main
from lapwrench.hardware.grip_identify import GripIdentifyError, config_snippet, identify, read_samples, run_config
from lapwrench.hardware.log import CycleRecord, RunLogger
from lapwrench.hardware.log.live_sim import SimTelemetry
from lapwrench.robot.arms import arm_spec
from lapwrench.robot.model import RobotModel
from lapwrench.sim.loop import ClosedLoop, observe_cycles
from lapwrench.sim.surgeon import HandGuide, rotate_axis
from lapwrench.wrenches.grip_weight import GRAVITY_B

MASS, COM = 0.12, np.array([0.004, -0.003, 0.012])
F_BIAS, T_BIAS = np.array([0.2, -0.1, 0.3]), np.array([0.005, 0.0, -0.004])
GOOD = 1500  # untouched, still cycles of the synthetic log
BOGUS = np.array([15.0, -20.0, 8.0])  # what a hand pushes: it must never reach the fit


def untouched_cycles(kind: str, n: int, seed: int = 0, tactile: bool = True, start: int = 0) -> list[CycleRecord]:
    """``n`` cycles of the untouched grip resting at random joints around the arm's home pose: the
    readings of lapwrench.wrenches.grip_weight's model with the sensor's bias and noise."""
    rng = np.random.default_rng(seed)
    model = RobotModel(kind)
    home = np.array(arm_spec(kind).home_pose)
    out = []
    for i in range(n):
        q = home + rng.uniform(-0.35, 0.35, home.size)
        u = model.placement_E_into(q)[0].T @ GRAVITY_B
        force = F_BIAS + MASS * u + 0.1 * rng.standard_normal(3)
        torque = T_BIAS + np.cross(COM, MASS * u) + 0.005 * rng.standard_normal(3)
        out.append(record(start + i, q=q, dq=np.zeros(home.size), ft_force=force, ft_torque=torque,
                          tactile=np.zeros(64) if tactile else None))
    return out


def spoilt_cycles(start: int, n: int = 100) -> list[CycleRecord]:
    """Cycles the fit must not see, ``n`` of each kind: gripped, the arm moving, no F/T, a NaN joint."""
    q = np.array(arm_spec("panda").home_pose)
    out = []
    for i in range(n):
        k = start + 4 * i
        out += [
            record(k, q=q, dq=np.zeros(7), ft_force=BOGUS, tactile=np.full(64, 40.0)),
            record(k + 1, q=q, dq=np.full(7, 0.2), ft_force=BOGUS, tactile=np.zeros(64)),
            record(k + 2, q=q, dq=np.zeros(7), ft_force=None, ft_torque=None, tactile=np.zeros(64)),
            record(k + 3, q=np.r_[q[:6], np.nan], dq=np.zeros(7), ft_force=BOGUS, tactile=np.zeros(64)),
        ]
    return out


def write_log(path: Path, cycles: Iterable[CycleRecord], cfg: config_mod.Config | None = None) -> Path:
    """A run log of ``cycles``, with ``cfg`` in its meta message as ``lapwrench run`` writes it."""
    cycles = list(cycles)
    meta: dict[str, Any] = {"command": "test"} if cfg is None else {"config": config_mod.to_dict(cfg)}
    with RunLogger(path, meta, capacity=len(cycles) + 1) as log:
        for c in cycles:
            log.cycle(c)
    return path


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("grip")
    cfg = config_mod.load()
    two_contacts = np.zeros(64)
    two_contacts[:2] = 200.0  # a grip only with k_min below 2
    strict = cfg.replace(interaction={"k_min": 1})
    return {
        "good": write_log(d / "good.mcap", [*untouched_cycles("panda", GOOD), *spoilt_cycles(GOOD)], cfg),
        "two_contacts": write_log(d / "two.mcap", [
            *untouched_cycles("panda", GOOD),
            *(record(GOOD + i, q=np.array(arm_spec("panda").home_pose), dq=np.zeros(7), ft_force=BOGUS,
                     tactile=two_contacts) for i in range(300)),
        ], strict),
        "ur5": write_log(d / "ur5.mcap", untouched_cycles("ur5", GOOD), cfg.replace(robot={"kind": "ur5"})),
        "no_meta": write_log(d / "no_meta.mcap", untouched_cycles("panda", GOOD)),
        "no_tactile": write_log(d / "no_tactile.mcap", untouched_cycles("panda", GOOD, tactile=False), cfg),
        "long": write_log(d / "long.mcap", untouched_cycles("panda", 3000, seed=1), cfg),
        "no_cycles": write_log(d / "no_cycles.mcap", [], cfg),
        "gripped": write_log(d / "gripped.mcap", spoilt_cycles(0)[::4], cfg),
        "moving": write_log(d / "moving.mcap", spoilt_cycles(0)[1::4], cfg),
        "no_tilt": write_log(d / "no_tilt.mcap", [record(i, dq=np.zeros(7), q=np.array(arm_spec("panda").home_pose),
                                                         tactile=np.zeros(64)) for i in range(500)], cfg),
    }


def assert_grip(mass: float, com: np.ndarray) -> None:
    assert mass == pytest.approx(MASS, abs=0.003)
    assert np.allclose(com, COM, atol=1e-3)


def test_a_logged_run_gives_the_grip_without_gripped_moving_or_broken_cycles(logs: dict[str, Path]) -> None:
    fit, samples = identify(logs["good"])
    assert_grip(fit.mass, fit.com)
    assert np.allclose(fit.force_bias, F_BIAS, atol=0.03) and np.allclose(fit.torque_bias, T_BIAS, atol=1e-3)
    assert samples.cycles == GOOD + 400 and samples.untouched == GOOD + 300 and samples.kept == GOOD
    assert fit.samples == GOOD and not samples.truncated


def test_many_cycles_are_subsampled_evenly(logs: dict[str, Path]) -> None:
    samples = read_samples(logs["good"], max_samples=500)
    assert samples.kept == GOOD and samples.R_H.shape == (500, 3, 3) and samples.force.shape == (500, 3)


def test_the_runs_own_configuration_tells_a_grip_from_an_untouched_handle(
    logs: dict[str, Path], tmp_path: Path
) -> None:
    """The log's interaction section (k_min 1) makes two contacts a grip; the defaults (k_min 3) do not."""
    samples = read_samples(logs["two_contacts"])
    assert samples.untouched == GOOD
    assert_grip(*identify(logs["two_contacts"])[0][:2])
    defaults = tmp_path / "defaults.yaml"
    defaults.write_text("robot: {kind: panda}\n")
    assert read_samples(logs["two_contacts"], config=str(defaults)).untouched == GOOD + 300


def test_the_runs_arm_gives_the_rotations(logs: dict[str, Path]) -> None:
    assert_grip(*identify(logs["ur5"])[0][:2])  # a six-joint arm, from the log's configuration
    with pytest.raises(GripIdentifyError, match="6 joints, the panda 7: give --robot"):
        identify(logs["ur5"], robot="panda")
    assert_grip(*identify(logs["no_meta"])[0][:2])  # no configuration in the log: the defaults (a panda)


def test_a_log_without_tactile_readings_needs_assume_untouched(logs: dict[str, Path]) -> None:
    with pytest.raises(GripIdentifyError, match=r"no tactile readings in 1500 cycles.*--assume-untouched"):
        identify(logs["no_tactile"])
    assert_grip(*identify(logs["no_tactile"], assume_untouched=True)[0][:2])


def test_the_speed_bound_keeps_a_moving_arm_out(logs: dict[str, Path]) -> None:
    with pytest.raises(GripIdentifyError, match=r"none had the arm still \(every \|dq\| <= 0.05 rad/s\)"):
        read_samples(logs["moving"])
    assert read_samples(logs["moving"], max_speed=0.3).kept == 100


def cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    try:
        code = main(["identify-grip", *argv])
    except SystemExit as exc:  # argparse's own errors
        code = exc.code if isinstance(exc.code, int) else 1
    out = capsys.readouterr()
    assert "Traceback" not in out.out + out.err
    return code, out.out, out.err


def pasted_config(out: str) -> config_mod.Config:
    """The configuration with the lines ``identify-grip`` says to paste."""
    return config_mod.from_dict(yaml.safe_load(out.split("paste into the configuration:\n", 1)[1]))


def test_the_command_prints_the_fit_and_lines_that_load_as_configuration(
    logs: dict[str, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    code, out, err = cli([str(logs["good"])], capsys)
    assert code == 0 and err == ""
    assert "mass            " in out and "g\n" in out and "mm in {H}" in out and "tilt span" in out
    cfg = pasted_config(out)
    assert_grip(cfg.scope.grip_mass, np.array(cfg.scope.grip_com))
    fit, _ = identify(logs["good"])
    assert config_snippet(fit) in out


def test_a_truncated_log_is_read_as_far_as_it_goes(
    logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = logs["long"].read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * 0.8)])
    code, out, err = cli([str(cut)], capsys)
    assert code == 0 and err.startswith(f"lapwrench identify-grip: {cut} is truncated; read ")
    read = int(err.split("read ")[1].split()[0])
    assert 0 < read < 3000
    cfg = pasted_config(out)
    assert_grip(cfg.scope.grip_mass, np.array(cfg.scope.grip_com))
    cut.write_bytes(data[:200])  # before the first cycle
    code, out, err = cli([str(cut)], capsys)
    assert code == 2 and "no /lapwrench/cycle messages (truncated before its first complete cycle)" in err


def bad_inputs(logs: dict[str, Path], tmp: Path) -> list[tuple[list[str], str]]:
    """(arguments, what the one line must say)."""
    (tmp / "text.mcap").write_text("not a log")
    (tmp / "empty.mcap").write_bytes(b"")
    (tmp / "folder").mkdir(exist_ok=True)
    return [
        ([str(tmp / "missing.mcap")], "no such log file"),
        ([str(tmp / "folder")], "is a directory"),
        ([str(tmp / "text.mcap")], "not an MCAP file"),
        ([str(tmp / "empty.mcap")], "empty file"),
        ([str(logs["no_cycles"])], "no /lapwrench/cycle messages"),
        ([str(logs["gripped"])], "the handle was gripped (or its tactile reading missing) in all 100 cycles"),
        ([str(logs["moving"])], "none had the arm still"),
        ([str(logs["no_tactile"])], "--assume-untouched"),
        ([str(logs["no_tilt"])], "the scope turned only 0.0°"),
        ([str(logs["ur5"]), "--robot", "panda"], "give --robot"),
        ([str(logs["good"]), "--robot", "kuka"], "--robot unknown robot 'kuka'"),
        ([str(logs["good"]), "--robot", "ur5e"], "--robot ur5e is not shipped"),
        ([str(logs["good"]), "--config", str(tmp / "missing.yaml")], "config file not found"),
        ([str(logs["good"]), "--max-speed", "nan"], "--max-speed: must be a number from 0 (excluded) to 5"),
        ([str(logs["good"]), "--max-speed", "-1"], "'-1'"),
        ([str(logs["good"]), "--max-speed", "0"], "'0'"),
        ([str(logs["good"]), "--max-speed", "x"], "'x'"),
        ([str(logs["good"]), "--max-speed", "inf"], "'inf'"),
        ([], "the following arguments are required: log"),
    ]


def test_every_bad_input_is_exit_2_and_one_line(
    logs: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for argv, says in bad_inputs(logs, tmp_path):
        code, out, err = cli(argv, capsys)
        lines = [line for line in err.splitlines() if line.strip() and not line.startswith(("usage:", " "))]
        assert code == 2, (argv, err)
        assert len(lines) == 1 and lines[0].startswith("lapwrench") and len(lines[0]) <= 400, (argv, err)
        assert says in lines[0], (argv, lines[0])
        assert out == ""


# ---------------------------------------------------------------------------------------- the simulator


def turned_untouched(path: Path, cfg: config_mod.Config) -> None:
    """A simulated run logged as ``lapwrench run`` logs it (the cycles, the configuration in the meta
    message): the hand turns the scope 15° about x, lets go, turns it 15° about y from where it started,
    lets go; a second untouched before, between and after. The F/T is the MuJoCo sensor under the grip."""
    meta = {"command": "test", "config": config_mod.to_dict(cfg)}
    with RunLogger(path, meta, capacity=100_000) as logger, observe_cycles(SimTelemetry(logger, every=1)):
        loop = ClosedLoop(cfg)
        _, down = loop.world.shaft_axis()
        for about in ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], None):
            for _ in range(1000):
                loop.step(0.0)
            if about is None:
                break
            hand = HandGuide(rotate_axis(down, about, 15.0), grip_force=24.0, max_force=25.0, max_speed=0.25,
                             tolerance_deg=1.5)
            while hand.engaged and loop.t < 30.0:
                loop.step(hand.apply(loop.world, loop.t, 1e-3))
        loop.close()


def test_a_simulated_run_gives_the_grip_the_simulator_carries(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """End to end: the MuJoCo world's grip (not the default one) from the log of a run in which the scope
    turned while nobody touched the handle (~15 s of simulated time)."""
    mass, com = 0.15, np.array([0.006, -0.004, 0.015])
    cfg = config_mod.load().replace(scope={"grip_mass": mass, "grip_com": com.tolist()})
    path = tmp_path / "sim.mcap"
    turned_untouched(path, cfg)
    code, out, err = cli([str(path)], capsys)
    assert code == 0, err
    fitted = pasted_config(out).scope
    assert fitted.grip_mass == pytest.approx(mass, rel=0.15)
    assert np.allclose(fitted.grip_com, com, atol=3e-3)
    fit, samples = identify(path)
    assert fit.tilt_span_deg > 15.0 and samples.kept < samples.untouched < samples.cycles  # gripped, then settling


def json_log(path: Path, cycles: list[dict[str, Any]]) -> Path:
    """A log whose cycles are JSON messages (the JSON-only logger's layout, or another program's)."""
    import json

    from mcap.writer import Writer

    from lapwrench.hardware.log import CYCLE_TOPIC

    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="", library="test")
        channel = writer.register_channel(topic=CYCLE_TOPIC, message_encoding="json", schema_id=0)
        for i, c in enumerate(cycles):
            writer.add_message(channel, log_time=i, publish_time=i, data=json.dumps(c).encode())
        writer.finish()
    return path


def test_fields_of_the_wrong_kind_are_missing_values_not_a_traceback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``"q": "abc"``, a joint given as text, a nested vector, an F/T reading as a mapping, an integer beyond
    any float: each ended identify-grip with a ValueError traceback. They are cycles without usable
    readings now: the good cycles around them still give the grip, and a log of nothing else is one line."""
    good = [c.to_dict() for c in untouched_cycles("panda", GOOD)]
    odd = [{**good[0], "q": "abc"}, {**good[0], "q": [0.1] * 6 + ["a"]}, {**good[0], "dq": [[0.0] * 7]},
           {**good[0], "ft_force": {"x": 1.0}}, {**good[0], "ft_torque": [10**400, 0, 0]},
           {**good[0], "tactile": "none"}, {**good[0], "q": 5}]
    code, out, err = cli([str(json_log(tmp_path / "mixed.mcap", odd + good + odd))], capsys)
    assert code == 0 and err == "", err
    assert f"{GOOD} of {GOOD + 2 * len(odd)} cycles untouched with the arm still" in out
    cfg = pasted_config(out)
    assert_grip(cfg.scope.grip_mass, np.array(cfg.scope.grip_com))
    code, out, err = cli([str(json_log(tmp_path / "odd.mcap", odd))], capsys)
    assert code == 2 and not out and len(err.strip().splitlines()) == 1
    assert err.startswith(f"lapwrench identify-grip: {tmp_path / 'odd.mcap'}: of ")


@pytest.mark.parametrize("logged", [[1, 2], "paper", 5])
def test_a_logged_configuration_that_is_not_a_mapping_is_refused_not_replaced_by_the_defaults(logged: Any) -> None:
    """It was taken as no configuration at all: the fit ran silently with the default arm and interaction
    section, which need not be the run's. --config still stands in for it."""
    with pytest.raises(GripIdentifyError, match=r"configuration is not a mapping of sections \(a \w+\); give"):
        run_config({"config": logged}, None, None)
    assert run_config({"config": logged}, "swapped-damping", None) == config_mod.load("swapped-damping")


def test_a_log_name_that_is_not_utf8_is_printed_escaped(logs: dict[str, Path], tmp_path: Path) -> None:
    """The fit's first line names the log: with stdout strict UTF-8 (a UTF-8 locale other than C.UTF-8), a
    name with a byte that is not UTF-8 ended identify-grip with a UnicodeEncodeError traceback."""
    import os
    import shutil
    import subprocess
    import sys

    log = tmp_path / os.fsdecode(b"run-\xff.mcap")
    shutil.copyfile(logs["good"], log)
    proc = subprocess.run([sys.executable, "-m", "lapwrench.cli", "identify-grip", str(log)], capture_output=True,
                          text=True, timeout=300, env={**os.environ, "PYTHONIOENCODING": "utf-8:strict"})
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert proc.stdout.startswith(f"grip identified from {tmp_path}/run-\\xff.mcap: ")
