"""``lapwrench run`` (the system on a Franka, or ``--dry-run`` in simulation) and ``lapwrench log-report``.

Wiring into the main command line (``lapwrench/cli.py``)::

    from lapwrench.hardware import cli as hw

    p_run = sub.add_parser("run", help="run on the robot (or --dry-run in simulation)")
    hw.add_run_arguments(p_run)
    p_run.set_defaults(func=hw.run_main)
    p_rep = sub.add_parser("log-report", help="plots from a run log")
    hw.add_log_report_arguments(p_rep)
    p_rep.set_defaults(func=hw.log_report_main)

Order of a run: configuration → every sensor device opened and checked (F/T streaming and tared
with the handle untouched, a first tactile frame, a first camera frame) → robot connected → loop.
A missing or unreachable device stops the run with an error naming it *before* the robot moves.

Processes (default): the 1 kHz loop runs in its own spawned process
(:mod:`lapwrench.hardware.rt`) with the robot, the controller, the supervisor and the F/T
socket (drained each cycle, no reader thread); the detector runs in another
(:mod:`lapwrench.hardware.detector_process`); this process keeps the tactile reader, the camera, the
MCAP writer and the command line, and feeds the loop through shared memory. ``--in-process`` runs
the former single-process loop (threads beside the loop; for debugging only).

``--dry-run`` runs the same pipeline on :class:`~lapwrench.sim.robot.SimRobot`: a
:class:`~lapwrench.drivers.simulated_hex.SimulatedHexBox` on 127.0.0.1 streams a scripted hand wrench that
the simulation applies to the handle at the same time, and a pty carries a simulated tactile grip
to the real :class:`~lapwrench.drivers.tactile.SerialTactileArray` reader. ``--frankysim`` does the
same against franky-sim (started here, on 127.0.0.1) through pylibfranka, as an FR3.

SIGINT, SIGTERM or SIGHUP asks the loop for a clean stop to rest (a second signal is ignored with
'please wait'); the summary names the signal (``stop_reason``) and the log is finalized. A signal
before the loop starts abandons the run with exit code 128 + its number (nothing has moved; see
:mod:`lapwrench.hardware.run_common`).

This module keeps the arguments and the checks before a run; the devices are opened in
:mod:`lapwrench.hardware.devices`, and the two run paths are :mod:`lapwrench.hardware.run_rt` (default)
and :mod:`lapwrench.hardware.run_inprocess` (``--in-process``).

Exit codes: 0 clean run (a requested stop that ends at rest is one), 1 the supervisor raised an
alarm, 2 a device or argument error, 3 a robot error (including the real-time process dying or
hanging).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path
from typing import Any

from lapwrench.cli_types import (
    FOXGLOVE_DEFAULT,
    ArgumentParser,
    cpu_list,
    float_in,
    hex_bytes,
    host_address,
    host_port,
    int_in,
    listen_problem,
    nonnegative_int,
    output_file,
    positive_float,
    quote,
    writable_file_problem,
)
from lapwrench.hardware.devices import (
    TACTILE_CHECKSUMS,
    CliError,
    DryRunScript,
    SimulatedHexProcess,
    parse_camera,
    parse_ft_url,
    tactile_format,
)
from lapwrench.hardware.franka import probe_command_port
from lapwrench.hardware.log import add_log_report_arguments, log_report_main
from lapwrench.hardware.run_inprocess import run_in_process
from lapwrench.hardware.run_rt import run_process

__all__ = [
    "CliError",
    "DryRunScript",
    "SimulatedHexProcess",
    "add_log_report_arguments",
    "add_run_arguments",
    "log_report_main",
    "parse_camera",
    "parse_ft_url",
    "run_main",
    "tactile_format",
]


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``lapwrench run`` (each value checked as it is parsed: :mod:`lapwrench.cli_types`)."""
    parser.add_argument("--robot-ip", type=host_address, help="Franka address (required unless --dry-run)")
    parser.add_argument(
        "--robot", metavar="NAME", default=None,
        help="the arm: panda or fr3 (default: the config's robot.kind; --frankysim is an fr3)",
    )
    parser.add_argument("--ft", help="handle F/T sensor: hex://HOST[:PORT] (OnRobot HEX) or ati://HOST[:PORT]")
    parser.add_argument("--tactile", help="tactile array serial port, e.g. /dev/ttyUSB0 (or a pyserial URL)")
    parser.add_argument(
        "--tactile-baud", type=int_in(1, 100_000_000), default=115200, help="tactile serial baud rate"
    )
    parser.add_argument(
        "--tactile-checksum",
        choices=TACTILE_CHECKSUMS,
        default=None,
        help="tactile frame checksum (default: the config's tactile.checksum)",
    )
    parser.add_argument(
        "--tactile-header",
        type=hex_bytes,
        default=None,
        metavar="HEX",
        help="tactile frame header bytes in hex, e.g. AA55 (default: the config's tactile.header)",
    )
    parser.add_argument("--camera", help="laparoscope camera: device index (0), video file or stream URL")
    parser.add_argument(
        "--detector",
        default=None,
        help="instrument detector on the --camera frames: classical (default), .onnx or .pt",
    )
    parser.add_argument("--config", help="YAML configuration (default: the packaged defaults)")
    parser.add_argument(
        "--duration", type=positive_float, default=None, help="seconds of robot time (default: until Ctrl-C)"
    )
    parser.add_argument("--log", type=output_file, help="record the run to this MCAP file")
    parser.add_argument(
        "--foxglove", nargs="?", const=host_port(FOXGLOVE_DEFAULT), type=host_port, default=None, metavar="HOST:PORT",
        help=f"serve the run live to Foxglove over a WebSocket (default {FOXGLOVE_DEFAULT}): the log's channels",
    )
    parser.add_argument("--dry-run", action="store_true", help="the full pipeline on the simulated robot")
    parser.add_argument("--realtime", choices=["enforce", "ignore"], default="enforce", help="libfranka realtime")
    parser.add_argument(
        "--ext-wrench-sign",
        choices=["robot_on_environment", "environment_on_robot"],
        default="robot_on_environment",
        help="sign of the Franka's O_F_ext_hat_K (libfranka documents robot_on_environment)",
    )
    parser.add_argument("--no-external-force", action="store_true", help="ignore the robot's force estimate")
    parser.add_argument(
        "--max-rcm-error",
        type=float_in(0.0, 0.1, lo_open=True),
        default=None,
        help="supervisor bound on the measured RCM error (m, at most 0.1; default: the config's"
        " safety.max_rcm_error)",
    )
    parser.add_argument(
        "--cycle-budget-us", type=float_in(0.0, 1e6, lo_open=True), default=800.0, help="compute time per cycle (us)"
    )
    parser.add_argument(
        "--max-misses", type=nonnegative_int, default=20, help="consecutive deadline misses that stop (0: never)"
    )
    parser.add_argument(
        "--ft-max-age", type=positive_float, default=0.02, help="F/T samples older than this are off (s)"
    )
    parser.add_argument("--tactile-max-age", type=positive_float, default=0.1, help="tactile max age (s)")
    parser.add_argument(
        "--camera-max-age", type=positive_float, default=0.2, help="instrument detection max age (s)"
    )
    parser.add_argument("--no-tare", action="store_true", help="do not tare the F/T sensor at start")
    parser.add_argument("--frankysim", action="store_true", help="--dry-run against franky-sim (pylibfranka, FR3)")
    parser.add_argument(
        "--in-process", action="store_true", help="debugging: run the loop in this process (threads, shared GIL)"
    )
    parser.add_argument(
        "--rt-priority",
        type=int_in(0, 99),
        default=80,
        help="SCHED_FIFO priority (0-99) of the loop's process (0: don't ask)",
    )
    parser.add_argument(
        "--rt-cpus", type=cpu_list, default=None, help="pin the loop's process to these CPUs, e.g. '1' or '2,3'"
    )
    parser.add_argument("--detector-cpus", type=cpu_list, default=None, help="pin the detector process to these CPUs")
    parser.add_argument(
        "--feeder-timeout",
        type=positive_float,
        default=0.5,
        help="heartbeat age (s) of this process that stops the loop",
    )
    parser.add_argument(
        "--detector-timeout",
        type=positive_float,
        default=1.0,
        help="heartbeat age (s) of the detector that stops the loop",
    )
    parser.add_argument(
        "--child-timeout",
        type=positive_float,
        default=None,
        help="heartbeat age (s) of the loop's process that counts as hung (default 0.5; 5 with a simulated robot,"
        " which may stall on a busy machine)",
    )


FRANKA_RATE_HZ = 1000.0


def run_main(args: argparse.Namespace) -> int:
    """``lapwrench run``. Returns the exit code (see the module docstring)."""
    from lapwrench import config as config_mod

    try:
        cfg = config_mod.load(args.config)
    except config_mod.ConfigError as exc:
        print(f"lapwrench run: {exc}", file=sys.stderr)
        return 2
    frankysim = bool(getattr(args, "frankysim", False))
    problem = _robot_problem(getattr(args, "robot", None), cfg)
    if problem:
        print(f"lapwrench run: {problem}", file=sys.stderr)
        return 2
    if getattr(args, "robot", None):
        cfg = cfg.replace(robot={"kind": args.robot})
    if frankysim:
        cfg = cfg.replace(robot={"kind": "fr3"})
    try:
        _check_run_arguments(args, cfg, simulated=bool(args.dry_run or frankysim))
        from lapwrench.controller import check_explicit_step_at_home

        check_explicit_step_at_home(cfg)  # else refused in the loop's process, as a robot error
    except (CliError, config_mod.ConfigError) as exc:
        print(f"lapwrench run: {exc}", file=sys.stderr)
        return 2
    if getattr(args, "in_process", False):
        if frankysim:
            print("lapwrench run: --frankysim runs in the process path only", file=sys.stderr)
            return 2
        return run_in_process(args, cfg)
    return run_process(args, cfg)


def _robot_problem(robot: str | None, cfg: Any) -> str | None:
    """Why ``run`` cannot drive ``robot`` (default: the config's arm), in one line, or ``None``. Only the
    arms whose spec has a hardware driver run here (the Franka arms); the others are simulation only."""
    from lapwrench.robot.arms import ARM_SPECS
    from lapwrench.robot_kinds import unknown_kind_message

    kind = robot or cfg.robot.kind
    if kind not in ARM_SPECS:
        return f"--robot {unknown_kind_message(kind)}"
    if not ARM_SPECS[kind].hardware:
        return f"{kind} has no hardware driver in lapwrench; simulation only (lapwrench demo --robot {kind})"
    return None


def _check_run_arguments(args: argparse.Namespace, cfg: Any, *, simulated: bool) -> None:
    """What argparse cannot check alone (combinations, the config, files, the robot's address):
    a :class:`CliError` names the problem before any device is opened. Fills in ``args.detector``
    (``classical`` when not given) and ``args.tactile_frame_format``."""
    if not simulated and not args.robot_ip:
        raise CliError("--robot-ip is required (or use --dry-run / --frankysim)")
    if simulated:
        mode = "--frankysim" if getattr(args, "frankysim", False) else "--dry-run"
        for flag, value in (("--robot-ip", args.robot_ip), ("--ft", args.ft), ("--tactile", args.tactile)):
            if value:  # silently ignored otherwise
                raise CliError(f"{flag} is not used with {mode}, which simulates the robot, the F/T sensor and the"
                               " tactile array; leave it out")
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        raise CliError("--duration must be a positive finite number of seconds")
    if cfg.robot.control_rate_hz != FRANKA_RATE_HZ:
        # the shaper and the supervisor would use the configured period while the robot
        # differentiates over 1 ms: at 500 Hz the commands ask 3.6x its acceleration limit
        raise CliError(
            f"robot.control_rate_hz must be {FRANKA_RATE_HZ:.0f} (the Franka differentiates every "
            f"command over 1 ms), got {cfg.robot.control_rate_hz}"
        )
    if args.ft:
        parse_ft_url(args.ft)
    _check_cues(cfg)
    _check_detector(args)
    args.tactile_frame_format = tactile_format(args, cfg)
    if args.log:
        problem = writable_file_problem(args.log)
        if problem:
            raise CliError(f"--log {quote(args.log)} {problem}")
    if getattr(args, "foxglove", None):
        problem = listen_problem(*args.foxglove)
        if problem:
            raise CliError(f"--foxglove {problem}")
    if not simulated:
        problem = probe_command_port(args.robot_ip)
        if problem:
            raise CliError(f"--robot-ip {problem}")


def _check_cues(cfg: Any) -> None:
    """The configured cues build, and every registered input they need has a driver for the robot
    (``InputSpec.open``; without one, the input runs in simulation only)."""
    from lapwrench.config_ranges import ConfigError
    from lapwrench.wrenches.registry import build_cues, input_specs

    try:
        cues = build_cues(cfg)
        specs = input_specs(cues)
    except ConfigError as exc:
        raise CliError(str(exc)) from exc
    for cue in cues:
        needs = [name for name in cue.inputs if name in specs and specs[name].open is None]
        if needs:
            raise CliError(f"cue {cue.name!r} needs input {needs[0]!r}, which has no driver for the robot "
                           "(InputSpec.open is None; it runs in simulation: lapwrench demo); switch the cue off "
                           "in 'cues:'")


def _check_detector(args: argparse.Namespace) -> None:
    """``--detector`` only means something with ``--camera``; a model file must exist."""
    if args.detector is None:
        args.detector = "classical"
        return
    if args.camera is None:
        raise CliError(f"--detector {quote(args.detector)} needs --camera (the detector runs on its frames)")
    if args.detector != "classical":
        path = Path(args.detector)
        if path.suffix.lower() not in (".onnx", ".pt"):
            raise CliError(f"--detector must be classical, a .onnx model or .pt weights, got {quote(args.detector)}")
        if not path.is_file():
            raise CliError(f"--detector model file {quote(args.detector)} not found")


def _main(argv: list[str] | None = None) -> int:
    """Stand-alone entry (``python -m lapwrench.hardware.cli run ...``) until the main CLI wires it."""
    parser = ArgumentParser(prog="lapwrench")
    sub = parser.add_subparsers(dest="cmd", required=True)
    p_run = sub.add_parser("run", help="run on the robot (or --dry-run in simulation)")
    add_run_arguments(p_run)
    p_rep = sub.add_parser("log-report", help="plots from a run log")
    add_log_report_arguments(p_rep)
    args = parser.parse_args(argv)
    return run_main(args) if args.cmd == "run" else log_report_main(args)


if __name__ == "__main__":
    os.environ.setdefault("MUJOCO_GL", "egl")
    raise SystemExit(_main())
