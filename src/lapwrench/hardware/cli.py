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
:class:`~lapwrench.drivers.fakes.FakeFTDevice` on 127.0.0.1 streams a scripted hand wrench that
the simulation applies to the handle at the same time, and a pty carries a simulated tactile grip
to the real :class:`~lapwrench.drivers.tactile.SerialTactileArray` reader. ``--frankysim`` does the
same against franky-sim (started here, on 127.0.0.1) through pylibfranka, as an FR3.

Ctrl-C or SIGTERM asks the loop for a clean stop to rest; the log is flushed and closed.

This module keeps the arguments and the checks before a run; the devices are opened in
:mod:`lapwrench.hardware.devices`, and the two run paths are :mod:`lapwrench.hardware.run_rt` (default)
and :mod:`lapwrench.hardware.run_inprocess` (``--in-process``).

Exit codes: 0 clean run, 1 the supervisor raised an alarm, 2 a device or argument error, 3 a robot
error (including the real-time process dying or hanging).
"""

from __future__ import annotations

import argparse
import os
import sys

from lapwrench.hardware.devices import CliError, DryRunScript, FakeFTProcess, parse_camera, parse_ft_url
from lapwrench.hardware.log import add_log_report_arguments, log_report_main
from lapwrench.hardware.run_inprocess import _run_in_process
from lapwrench.hardware.run_rt import _run_process

__all__ = [
    "CliError",
    "DryRunScript",
    "FakeFTProcess",
    "add_log_report_arguments",
    "add_run_arguments",
    "log_report_main",
    "parse_camera",
    "parse_ft_url",
    "run_main",
]


def add_run_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``lapwrench run``."""
    parser.add_argument("--robot-ip", help="Franka address (required unless --dry-run)")
    parser.add_argument("--ft", help="handle F/T sensor: hex://HOST[:PORT] (OnRobot HEX) or ati://HOST[:PORT]")
    parser.add_argument("--tactile", help="tactile array serial port, e.g. /dev/ttyUSB0 (or a pyserial URL)")
    parser.add_argument("--tactile-baud", type=int, default=115200, help="tactile serial baud rate")
    parser.add_argument("--camera", help="laparoscope camera: device index (0), video file or stream URL")
    parser.add_argument("--detector", default="classical", help="instrument detector: classical, .onnx or .pt")
    parser.add_argument("--config", help="YAML configuration (default: the packaged defaults)")
    parser.add_argument("--duration", type=float, default=None, help="seconds of robot time (default: until Ctrl-C)")
    parser.add_argument("--log", help="record the run to this MCAP file")
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
        type=float,
        default=None,
        help="supervisor bound on the measured RCM error (m; default: the config's safety.max_rcm_error)",
    )
    parser.add_argument("--cycle-budget-us", type=float, default=800.0, help="compute time per cycle (us)")
    parser.add_argument("--max-misses", type=int, default=20, help="consecutive deadline misses that stop")
    parser.add_argument("--ft-max-age", type=float, default=0.02, help="F/T samples older than this are off (s)")
    parser.add_argument("--tactile-max-age", type=float, default=0.1, help="tactile max age (s)")
    parser.add_argument("--camera-max-age", type=float, default=0.2, help="instrument detection max age (s)")
    parser.add_argument("--no-tare", action="store_true", help="do not tare the F/T sensor at start")
    parser.add_argument("--frankysim", action="store_true", help="--dry-run against franky-sim (pylibfranka, FR3)")
    parser.add_argument(
        "--in-process", action="store_true", help="debugging: run the loop in this process (threads, shared GIL)"
    )
    parser.add_argument(
        "--rt-priority", type=int, default=80, help="SCHED_FIFO priority of the loop's process (0: don't ask)"
    )
    parser.add_argument("--rt-cpus", default=None, help="pin the loop's process to these CPUs, e.g. '1' or '2,3'")
    parser.add_argument("--detector-cpus", default=None, help="pin the detector process to these CPUs")
    parser.add_argument(
        "--feeder-timeout", type=float, default=0.5, help="heartbeat age (s) of this process that stops the loop"
    )
    parser.add_argument(
        "--detector-timeout", type=float, default=1.0, help="heartbeat age (s) of the detector that stops the loop"
    )
    parser.add_argument(
        "--child-timeout",
        type=float,
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
    if frankysim:
        cfg = cfg.replace(robot={"kind": "fr3"})
    if not (args.dry_run or frankysim) and not args.robot_ip:
        print("lapwrench run: --robot-ip is required (or use --dry-run / --frankysim)", file=sys.stderr)
        return 2
    if args.duration is not None and not args.duration > 0:
        print("lapwrench run: --duration must be positive", file=sys.stderr)
        return 2
    if cfg.robot.control_rate_hz != FRANKA_RATE_HZ:
        # the shaper and the supervisor would use the configured period while the robot
        # differentiates over 1 ms: at 500 Hz the commands ask 3.6x its acceleration limit
        print(
            f"lapwrench run: robot.control_rate_hz must be {FRANKA_RATE_HZ:.0f} (the Franka differentiates every "
            f"command over 1 ms), got {cfg.robot.control_rate_hz}",
            file=sys.stderr,
        )
        return 2
    if getattr(args, "in_process", False):
        if frankysim:
            print("lapwrench run: --frankysim runs in the process path only", file=sys.stderr)
            return 2
        return _run_in_process(args, cfg)
    return _run_process(args, cfg)


def _main(argv: list[str] | None = None) -> int:
    """Stand-alone entry (``python -m lapwrench.hardware.cli run ...``) until the main CLI wires it."""
    parser = argparse.ArgumentParser(prog="lapwrench")
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
