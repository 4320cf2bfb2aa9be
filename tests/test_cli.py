"""The ``lapwrench`` command line refuses every bad argument and input file cleanly (issue 11, item 10):
exit code 2, one line on stderr naming the argument or file (argparse adds its usage line), and
never a traceback. Also the argument types of :mod:`lapwrench.cli_types` themselves."""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from lapwrench import cli_types
from lapwrench.cli import main
from lapwrench.hardware.log.topics import CYCLE_TOPIC

ONNX_GARBAGE = b"not an onnx model"


@pytest.fixture
def files(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A working folder with hostile inputs: a plain file (a path under it cannot be written, even as
    root), a non-UTF-8 config, a config with a 400-digit number, and a model that is not one."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "afile").write_text("x")
    (tmp_path / "latin1.yaml").write_bytes(b"robot: {kind: panda}\n# \xe9t\xe9\n")
    (tmp_path / "huge.yaml").write_text(f"camera: {{fx: {'9' * 400}}}\n")
    (tmp_path / "bad.onnx").write_bytes(ONNX_GARBAGE)
    (tmp_path / "image.png").write_bytes(b"not a png")
    return tmp_path


def run_cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    """``lapwrench.cli.main(argv)`` → (exit code, stderr); an exception fails the test (a traceback)."""
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse's own errors
        code = exc.code if isinstance(exc.code, int) else 1
    return code, capsys.readouterr().err


def message_lines(err: str) -> list[str]:
    """stderr without argparse's usage block (``usage:`` and its indented continuation lines)."""
    return [line for line in err.splitlines() if line.strip() and not line.startswith(("usage:", " "))]


BAD_ARGUMENTS: list[list[str]] = [
    # virtual
    ["virtual", "--duration", "0"],
    ["virtual", "--duration", "-1"],
    ["virtual", "--duration", "nan"],
    ["virtual", "--duration", "inf"],
    ["virtual", "--duration", "1e9"],
    ["virtual", "--duration", "3600"],  # every tick kept: 17 GB
    ["virtual", "--duration", "0.0001"],  # no tick at all
    ["virtual", "--duration", "ten"],
    ["virtual", "--out", "afile/sub"],
    ["virtual", "--out", "afile"],
    ["virtual", "--config", "latin1.yaml", "--out", "v"],
    ["virtual", "--config", "huge.yaml", "--out", "v"],
    ["virtual", "--config", "missing.yaml", "--out", "v"],
    # demo
    ["demo", "--seed", "-1"],
    ["demo", "--seed", "1" * 5000],
    ["demo", "--seed", "4294967296"],
    ["demo", "--time-scale", "0"],
    ["demo", "--time-scale", "nan"],
    ["demo", "--time-scale", "2"],
    ["demo", "--workers", "0"],
    ["demo", "--workers", "-3"],
    ["demo", "--workers", "x"],
    ["demo", "--out", "afile/report"],
    ["demo", "--out", "afile"],
    ["demo", "--out", ""],
    ["demo", "--scenarios", "laparotomy", "--out", "d"],
    ["demo", "--config", "latin1.yaml", "--out", "d"],
    ["demo", "--config", "huge.yaml", "--out", "d"],
    ["demo", "--tracking-config", "missing.yaml", "--out", "d"],
    ["demo", "--detector", "bad.onnx", "--out", "d"],
    ["demo", "--detector", "bad.onnx", "--scenarios", "grip", "--out", "d"],
    ["demo", "--detector", "missing.onnx", "--out", "d"],
    ["demo", "--detector", "afile", "--out", "d"],
    # run
    ["run", "--dry-run", "--duration", "0"],
    ["run", "--dry-run", "--duration", "nan"],
    ["run", "--dry-run", "--max-rcm-error", "-1"],
    ["run", "--dry-run", "--max-rcm-error", "nan"],
    ["run", "--dry-run", "--ft-max-age", "nan"],
    ["run", "--dry-run", "--tactile-max-age", "-0.1"],
    ["run", "--dry-run", "--camera-max-age", "0"],
    ["run", "--dry-run", "--cycle-budget-us", "0"],
    ["run", "--dry-run", "--cycle-budget-us", "inf"],
    ["run", "--dry-run", "--max-misses", "-1"],
    ["run", "--dry-run", "--max-misses", "2.5"],
    ["run", "--dry-run", "--tactile-baud", "0"],
    ["run", "--dry-run", "--rt-priority", "100"],
    ["run", "--dry-run", "--rt-priority", "-1"],
    ["run", "--dry-run", "--rt-cpus", "a,b"],
    ["run", "--dry-run", "--rt-cpus", "100000"],
    ["run", "--dry-run", "--detector-cpus", "1,,2"],
    ["run", "--dry-run", "--feeder-timeout", "0"],
    ["run", "--dry-run", "--detector-timeout", "nan"],
    ["run", "--dry-run", "--child-timeout", "-5"],
    ["run", "--dry-run", "--tactile-checksum", "md5"],
    ["run", "--dry-run", "--tactile-header", "ZZ"],
    ["run", "--dry-run", "--tactile-header", ""],
    ["run", "--dry-run", "--tactile-header", "AA5"],
    ["run", "--dry-run", "--log", "afile/x.mcap"],
    ["run", "--dry-run", "--log", "."],
    ["run", "--dry-run", "--config", "latin1.yaml"],
    ["run", "--dry-run", "--config", "huge.yaml"],
    ["run", "--dry-run", "--detector", "bad.onnx"],  # no --camera
    ["run", "--dry-run", "--camera", "v.avi", "--detector", "missing.onnx"],
    ["run", "--dry-run", "--camera", "v.avi", "--detector", "model.txt"],
    ["run", "--robot-ip", "300.1.2.3"],
    ["run", "--robot-ip", ""],
    ["run", "--robot-ip", "bad host name"],
    ["run", "--robot-ip", "-x-.example"],
    ["run", "--ft", "hex://1.2.3.4"],  # no --robot-ip and no --dry-run
    ["run", "--dry-run", "--realtime", "x" * 5000],
    # log-report
    ["log-report", "missing.mcap"],
    # dataset
    ["dataset", "--train", "-1"],
    ["dataset", "--val", "x"],
    ["dataset", "--test", "1e3"],
    ["dataset", "--seed", "-1"],
    ["dataset", "--splits", "train,holdout"],
    ["dataset", "--splits", ","],
    ["dataset", "--out", "afile/ds"],
    ["dataset", "--out", "afile"],
    ["dataset", "--train", "0", "--val", "0", "--test", "0", "--out", "ds"],
    # train
    ["train", "--epochs", "0"],
    ["train", "--batch", "0"],
    ["train", "--imgsz", "-320"],
    ["train", "--time-hours", "nan"],
    ["train", "--workers", "-1"],
    ["train", "--threads", "0"],
    ["train", "--lr0", "-0.1"],
    ["train", "--warmup-epochs", "-1"],
    ["train", "--close-mosaic", "-1"],
    ["train", "--scale", "xl"],
    ["train", "--export-hw", "256x"],
    ["train", "--export-hw", "250x320"],
    ["train", "--name", "../escape"],
    ["train", "--out", "afile/runs"],
    ["train", "--ship", "afile/m.onnx"],
    ["train", "--data", "missing.yaml"],
    # calibrate
    ["calibrate", "image.png", "--square", "0"],
    ["calibrate", "image.png", "--square", "nan"],
    ["calibrate", "image.png", "--min-views", "0"],
    ["calibrate", "image.png", "--board", "1x1"],
    ["calibrate", "image.png", "--board", "9x"],
    ["calibrate", "image.png", "--out", "afile/i.yaml"],
    ["calibrate", "image.png", "--out", "."],
    ["calibrate", "missing_*.png", "--out", "i.yaml"],
    ["calibrate", "image.png", "--out", "i.yaml"],  # not an image
    # the command itself
    ["laparotomy"],
    [],
]


@pytest.mark.parametrize("argv", BAD_ARGUMENTS, ids=lambda a: " ".join(a)[:60] or "(none)")
def test_every_bad_argument_is_exit_2_and_one_short_line(
    argv: list[str], files: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, err = run_cli(argv, capsys)
    lines = message_lines(err)
    assert code == 2, err
    assert "Traceback" not in err
    assert len(lines) == 1, err
    assert len(lines[0]) <= 400, lines[0][:500]
    assert lines[0].startswith("lapwrench"), lines[0]
    assert not (files / "d" / "report.md").exists()


def test_bad_values_are_named_and_quoted_short(files: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, err = run_cli(["virtual", "--duration", "nan"], capsys)
    assert code == 2 and "--duration" in err and "'nan'" in err
    code, err = run_cli(["demo", "--seed", "7" * 5000], capsys)
    assert code == 2 and "--seed" in err and "7" * 61 not in err
    code, err = run_cli(["run", "--dry-run", "--log", "afile/x.mcap"], capsys)
    assert code == 2 and "--log" in err and "afile" in err and "not a folder" in err
    code, err = run_cli(["run", "--dry-run", "--config", "latin1.yaml"], capsys)
    assert code == 2 and "latin1.yaml" in err
    code, err = run_cli(["run", "--dry-run", "--detector", "bad.onnx"], capsys)
    assert code == 2 and "--detector" in err and "--camera" in err


def test_a_bad_detector_model_is_refused_before_the_old_report_is_touched(
    files: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Issue 11 item 8: the model is loaded while planning, whatever the scenarios (grip has no
    detector), so a bad one never costs a simulation nor deletes the previous report."""
    out = files / "report"
    out.mkdir()
    (out / "report.md").write_text("previous report")
    (out / "metrics.json").write_text("{}")
    for scenarios in (["grip"], ["needle-search"]):
        code, err = run_cli(["demo", "--detector", "bad.onnx", "--scenarios", *scenarios, "--out", str(out)], capsys)
        assert code == 2 and "bad.onnx" in err, err
        assert (out / "report.md").read_text() == "previous report" and (out / "metrics.json").exists()


def test_the_entry_point_prints_no_traceback(files: Path) -> None:
    """Through ``python -m lapwrench.cli`` (a few representative vectors; the table above covers the rest
    in this process)."""
    env = {**os.environ, "MUJOCO_GL": "egl"}
    for argv in (["virtual", "--duration", "inf"], ["demo", "--config", "latin1.yaml", "--out", "d"],
                 ["run", "--dry-run", "--log", "afile/x.mcap"], ["calibrate", "x.png", "--out", "."]):
        proc = subprocess.run([sys.executable, "-m", "lapwrench.cli", *argv], capture_output=True, text=True,
                              env=env, timeout=120, check=False)
        assert proc.returncode == 2, proc.stderr
        assert "Traceback" not in proc.stderr and len(message_lines(proc.stderr)) == 1, proc.stderr


def test_long_argparse_errors_are_cut_to_one_short_line(capsys: pytest.CaptureFixture[str]) -> None:
    parser = cli_types.ArgumentParser(prog="p")
    parser.add_argument("--mode", choices=["a", "b"])
    with pytest.raises(SystemExit):
        parser.parse_args(["--mode", "m" * 10_000])
    line = message_lines(capsys.readouterr().err)
    assert len(line) == 1 and len(line[0]) <= cli_types.MAX_MESSAGE_CHARS + 20


def test_a_detector_failing_during_the_run_leaves_failed_txt(
    files: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A failure inside a scenario (here a detector error) is a runtime failure, exit 1 (not an argument
    error), with one line and a FAILED.txt that says why, in place of the report deleted at the start."""
    from lapwrench.perception import ModelError
    from lapwrench.sim import demo as demo_mod

    def broken(cfg: object, opts: object) -> None:
        raise ModelError("model.onnx", "inference failed")

    monkeypatch.setitem(demo_mod.SCENARIOS, "grip", broken)
    out = files / "report"
    code, err = run_cli(["demo", "--scenarios", "grip", "--workers", "1", "--no-video", "--quiet",
                         "--detector", "projected", "--out", str(out)], capsys)
    assert code == 1 and "Traceback" not in err and len(message_lines(err)) == 1, err
    assert "inference failed" in err
    failed = (out / "FAILED.txt").read_text()
    assert "inference failed" in failed and "ModelError" in failed
    assert not (out / "report.md").exists()


def test_demo_refuses_a_foxglove_port_in_use_before_anything_runs(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        code, err = run_cli(["demo", "--scenarios", "grip", "--foxglove", f"127.0.0.1:{port}", "--out",
                             str(tmp_path / "out")], capsys)
    assert code == 2 and f"--foxglove cannot listen on 127.0.0.1:{port}" in err and err.count("\n") == 1
    assert not (tmp_path / "out" / "report.md").exists()



def _advertised_telemetry(port: int) -> list[str]:
    """The cues the ``lapwrench.Telemetry`` part of the cycle channel's schema names, as a Foxglove
    client connecting to ``port`` is told."""
    import asyncio
    import base64
    import json

    import websockets
    from google.protobuf.descriptor_pb2 import FileDescriptorSet

    async def advertised() -> bytes:
        async with websockets.connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"]) as ws:
            while True:
                op = json.loads(await asyncio.wait_for(ws.recv(), 10.0))
                if op["op"] == "advertise":
                    return next(base64.b64decode(c["schema"]) for c in op["channels"] if c["topic"] == CYCLE_TOPIC)

    (file,) = FileDescriptorSet.FromString(asyncio.run(advertised())).file
    return [f.name for f in next(m for m in file.message_type if m.name == "Telemetry").field]


def test_demo_foxglove_streams_the_cue_telemetry_of_its_configs_and_of_every_cue_type(
    files: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``demo --foxglove`` serves the cue telemetry of both its configs (the tracking scenarios' own)
    under their names, then of the cue types a scenario adds by type (zoom, keep_out); the
    scenarios are replaced by a Foxglove client reading the cycle schema the server advertises."""
    import re

    from lapwrench.sim import demo

    pytest.importorskip("websockets")
    zone = "{type: keep_out, center: [0.9, 0.0, 0.1], radius: 0.05}"
    (files / "base.yaml").write_text(f"cues:\n  near: {zone}\n")
    (files / "track.yaml").write_text(f"cues:\n  far: {zone}\n")
    seen: list[str] = []

    def run_demo(plan: object, progress: bool) -> dict[str, object]:
        port = int(re.findall(r"live telemetry for Foxglove on ws://127\.0\.0\.1:(\d+)", capsys.readouterr().err)[0])
        seen.extend(_advertised_telemetry(port))
        return {}

    monkeypatch.setattr(demo, "run_demo", run_demo)
    code, err = run_cli(["demo", "--scenarios", "grip", "workflow", "--config", "base.yaml", "--tracking-config",
                         "track.yaml", "--detector", "projected", "--foxglove", "127.0.0.1:0", "--out", "out"], capsys)
    assert code == 0, err
    assert seen[:2] == ["near", "far"] and {"keep_out", "zoom"} <= set(seen)


@pytest.mark.parametrize("command", [["log-report", "run.mcap"], ["identify-grip", "run.mcap"]])
def test_ctrl_c_in_a_command_is_one_line_and_exit_130(
    command: list[str], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """Commands without their own Ctrl-C handling (reading a long log) end with one line, not a traceback."""
    from lapwrench.hardware import cli as hardware_cli
    from lapwrench.hardware import grip_identify

    def interrupted(*_args: object, **_kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(hardware_cli, "log_report_main", interrupted)
    monkeypatch.setattr(grip_identify, "identify", interrupted)
    assert main(command) == 130
    err = capsys.readouterr().err
    assert err == f"lapwrench {command[0]}: interrupted\n"


class NotHandledError(Exception):
    """What the test's own SIGTERM handler raises: main() left the signal to it (it would end the tests)."""


def _assert_log_report_stopped_by_sigterm(
    command: Callable[..., int], monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``lapwrench log-report`` running ``command`` (which meets a SIGTERM) ends with the stop's line and 143;
    SIGTERM's handler outside the command raises (a test that reached it would fail)."""
    from lapwrench.hardware import cli as hardware_cli

    def not_handled(*_args: object) -> None:
        raise NotHandledError

    monkeypatch.setattr(hardware_cli, "log_report_main", command)
    before = signal.signal(signal.SIGTERM, not_handled)
    try:
        assert main(["log-report", "run.mcap"]) == 143
    finally:
        signal.signal(signal.SIGTERM, before)
    assert capsys.readouterr().err == "lapwrench log-report: stopped by SIGTERM\n"


def test_sigterm_in_a_command_is_one_line_and_exit_143(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """SIGTERM (``kill``, a service manager) ends a command as Ctrl-C does, with its own number."""

    def killed(*_args: object) -> int:
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(30)  # the signal stops it here (within cli_signals.WAIT_S: this code is not lapwrench's)
        return 0

    _assert_log_report_stopped_by_sigterm(killed, monkeypatch, capsys)


@pytest.mark.parametrize("how", ["swallowed", "still waiting"])
def test_a_command_that_ends_after_a_stop_signal_never_exits_0(
    how: str, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A stop whose exception something swallowed on its way (a library's ``except BaseException``), or that
    still waited for lapwrench's own code when the command returned (this test's code is not lapwrench's):
    the command ran on to its end, but its exit code and line are the stop's, not 0 (a service manager's
    SIGTERM must never look like a finished run)."""

    def signalled(*_args: object) -> int:
        if how == "swallowed":
            with contextlib.suppress(BaseException):
                signal.raise_signal(signal.SIGTERM)
                time.sleep(30)  # the signal stops it here
        else:
            signal.raise_signal(signal.SIGTERM)  # taken here, where it cannot be raised: it waits
        return 0

    _assert_log_report_stopped_by_sigterm(signalled, monkeypatch, capsys)


def test_an_error_on_the_way_out_after_ctrl_c_is_the_stop_line(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A clean-up that fails on what the signal cut short (a module cut halfway that it imports again, as
    pandas did in ``sweep``) still ends with the one line of the stop, not the clean-up's traceback."""
    from lapwrench.hardware import cli as hardware_cli

    def interrupted(*_args: object) -> int:
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(30)
        except KeyboardInterrupt:
            raise AttributeError("partially initialized module 'pandas' has no attribute 'x'") from None
        return 0

    monkeypatch.setattr(hardware_cli, "log_report_main", interrupted)
    before = signal.signal(signal.SIGINT, signal.default_int_handler)  # whatever the runner left (SIG_IGN)
    try:
        assert main(["log-report", "run.mcap"]) == 130
    finally:
        signal.signal(signal.SIGINT, before)
    assert capsys.readouterr().err == "lapwrench log-report: interrupted\n"


@pytest.mark.parametrize("command", [["virtual", "--duration", "0.5", "--quiet"], ["log-report", "{log}"]])
def test_a_reader_that_went_away_is_one_line_and_141_not_a_broken_pipe_traceback(
    command: list[str], tmp_path: Path
) -> None:
    """``lapwrench ... | head -1``: the printing after the reader has gone raised BrokenPipeError, a traceback.
    Now one line on stderr and 128 + SIGPIPE, as a program SIGPIPE ends (here the reader is gone at once)."""
    from hardware.log.support import write

    log = tmp_path / "run.mcap"
    write(log, 50)
    argv = [a.format(log=log) for a in command]
    proc = subprocess.Popen([sys.executable, "-m", "lapwrench", *argv, "--out", str(tmp_path / "out")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env={**os.environ, "MUJOCO_GL": "egl"})
    assert proc.stdout is not None and proc.stderr is not None
    proc.stdout.close()
    err = proc.stderr.read()
    assert proc.wait(timeout=300) == 128 + signal.SIGPIPE, err
    assert err == f"lapwrench {command[0]}: its output was closed (the reading end of a pipe); stopped\n"


def test_a_report_folder_whose_name_is_not_utf8_is_printed_escaped(tmp_path: Path) -> None:
    """With stdout strict UTF-8 (a UTF-8 locale other than C.UTF-8), ``virtual``'s last line ("wrote ...")
    ended it with a UnicodeEncodeError traceback, after the report was written."""
    out = tmp_path / os.fsdecode(b"virtual-\xff")
    proc = subprocess.run([sys.executable, "-m", "lapwrench", "virtual", "--duration", "0.2", "--quiet", "--out",
                           str(out)], capture_output=True, text=True, timeout=300,
                          env={**os.environ, "PYTHONIOENCODING": "utf-8:strict"})
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert proc.stdout.splitlines()[-1].startswith(f"wrote {tmp_path}/virtual-\\xff/virtual_closed_loop.png")


def test_a_robot_description_that_cannot_be_used_is_one_line_and_exit_2(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A damaged installed description (or an arm spec pointing at a bad file) is the user's to fix: one
    line naming the file, exit 2, not a traceback."""
    import dataclasses

    from lapwrench.robot.arms import ARM_SPECS, UrdfFile

    bad = tmp_path / "arm.urdf"
    bad.write_text("<robot name='x'><link name='a'/></robot>")
    monkeypatch.setitem(ARM_SPECS, "panda", dataclasses.replace(ARM_SPECS["panda"], description=UrdfFile(bad)))
    code, err = run_cli(["virtual", "--duration", "0.1", "--quiet", "--out", str(tmp_path / "out")], capsys)
    assert code == 2
    assert message_lines(err) == [f"lapwrench virtual: {bad}: no link 'panda_link0' (the panda spec's base or flange)"]


def test_a_plugin_cue_that_fails_while_the_controller_is_built_is_one_line_naming_it(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The controller's warm-up tick runs every cue before anything moves: a plugin that raises there is the
    user's to fix, one line naming the cue and what it raised, exit 2 (it was the plugin's own traceback)."""
    import fake_plugins

    from lapwrench import plugins
    from lapwrench.wrenches.base import Cue, TickContext

    class Broken(Cue):
        def compute(self, ctx: TickContext) -> object:
            raise ZeroDivisionError("division by zero")

    fake_plugins.install(monkeypatch)
    monkeypatch.setitem(fake_plugins.FAKE[plugins.CUE_GROUP], "broken", Broken)
    (tmp_path / "c.yaml").write_text("cues:\n  broken: {}\n")
    code, err = run_cli(["virtual", "--config", str(tmp_path / "c.yaml"), "--duration", "0.1", "--quiet", "--out",
                         str(tmp_path / "out")], capsys)
    assert code == 2
    assert message_lines(err) == ["lapwrench virtual: cue 'broken' compute: ZeroDivisionError: division by zero"]
