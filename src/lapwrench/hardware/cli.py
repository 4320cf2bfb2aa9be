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

``--dry-run`` runs the same pipeline, threads included, on :class:`~lapwrench.sim.robot.SimRobot`:
a :class:`~lapwrench.drivers.fakes.FakeFTDevice` on 127.0.0.1 streams a scripted hand wrench that
the simulation applies to the handle at the same time, and a pty carries a simulated tactile grip
to the real :class:`~lapwrench.drivers.tactile.SerialTactileArray` reader.

Exit codes: 0 clean run, 1 the supervisor raised an alarm, 2 a device or argument error, 3 a robot
error.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import signal
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any
from urllib.parse import urlsplit

import numpy as np

from lapwrench.hardware.log import add_log_report_arguments, log_report_main

__all__ = ["DryRunScript", "add_log_report_arguments", "add_run_arguments", "log_report_main", "run_main"]


class CliError(Exception):
    """An argument or device problem reported as ``lapwrench run: <message>`` with exit code 2."""


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


# -- device specs -------------------------------------------------------------------------------
def parse_ft_url(url: str) -> tuple[str, str, int]:
    """``hex://HOST[:PORT]`` / ``ati://HOST[:PORT]`` → (kind, host, port)."""
    parts = urlsplit(url)
    if parts.scheme not in ("hex", "ati") or not parts.hostname:
        raise CliError(f"--ft must be hex://HOST[:PORT] or ati://HOST[:PORT], got {url!r}")
    try:
        port = parts.port or 49152
    except ValueError as exc:
        raise CliError(f"--ft {url!r}: bad port") from exc
    return parts.scheme, parts.hostname, port


def parse_camera(spec: str) -> int | str:
    """A device index for digits, otherwise the file path or URL."""
    return int(spec) if spec.isdigit() else spec


# -- the dry-run script ---------------------------------------------------------------------------
@dataclass
class DryRunScript:
    """The scripted surgeon of ``--dry-run`` (times in s since the script's start, wall clock).

    The handle is untouched for ``tare_s`` (the F/T tare happens then), gripped from ``grip[0]`` to
    ``grip[1]``, and pushed with the force segments ``(t_start, t_end, force in {H})``.
    """

    tare_s: float = 1.0
    grip: tuple[float, float] = (1.2, 5.8)
    grip_value: int = 40
    pushes: list[tuple[float, float, tuple[float, float, float]]] = field(
        default_factory=lambda: [(1.5, 3.5, (6.0, 0.0, 0.0)), (4.0, 5.5, (0.0, -5.0, 0.0))]
    )
    t0: float = field(default_factory=time.monotonic)

    def now(self) -> float:
        return time.monotonic() - self.t0

    def force_H(self, t: float | None = None) -> np.ndarray:
        t = self.now() if t is None else t
        for a, b, f in self.pushes:
            if a <= t < b:
                return np.array(f, dtype=float)
        return np.zeros(3)

    def tactile(self, t: float | None = None) -> np.ndarray:
        t = self.now() if t is None else t
        on = self.grip[0] <= t < self.grip[1]
        return np.full(64, self.grip_value if on else 0, dtype=np.uint8)


class _TactileWriter:
    """Writes tactile frames of a script to a pty master at ``rate_hz`` (the simulated grip array)."""

    def __init__(self, fd: int, values: Callable[[], np.ndarray], rate_hz: float = 200.0) -> None:
        from lapwrench.drivers.tactile import TactileFrameFormat

        self.fd = fd
        self.values = values
        self.period = 1.0 / rate_hz
        self.fmt = TactileFrameFormat()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="lapwrench-sim-tactile", daemon=True)

    def start(self) -> _TactileWriter:
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(2.0)

    def _run(self) -> None:
        while not self._stop.is_set():
            with contextlib.suppress(OSError):
                os.write(self.fd, self.fmt.encode(self.values()))
            self._stop.wait(self.period)


# -- the run ------------------------------------------------------------------------------------
class _Devices:
    """Opened devices, closed in reverse order."""

    def __init__(self) -> None:
        self._closers: list[Callable[[], None]] = []

    def add(self, closer: Callable[[], None]) -> None:
        self._closers.append(closer)

    def close(self) -> None:
        while self._closers:
            with contextlib.suppress(Exception):
                self._closers.pop()()


def _open_sources(
    args: argparse.Namespace, cfg: Any, devices: _Devices, script: DryRunScript | None
) -> tuple[Any, dict[str, str]]:
    """Open, check and start every sensor source; return (Sources, device descriptions).

    The camera's frames must have the size of the configured intrinsics (``camera.width`` x
    ``camera.height``), which the tracking wrench projects with: a mismatch fails at start.
    """
    from lapwrench.drivers import AtiNetFTSensor, DeviceError, OnRobotHexSensor, SerialTactileArray
    from lapwrench.hardware.runner import DetectorWorker, Sources

    sources = Sources()
    described: dict[str, str] = {}
    ft_url, tactile_port = args.ft, args.tactile
    if script is not None:
        from lapwrench.drivers.fakes import FakeFTDevice

        def counts(_i: int) -> np.ndarray:
            f = script.force_H()
            return np.concatenate([f * 10000.0, np.zeros(3)]).round()

        fake = FakeFTDevice(rate_hz=1000.0, counts_fn=counts).start()
        devices.add(fake.close)
        ft_url = f"hex://127.0.0.1:{fake.port}"
        master, slave = os.openpty()
        devices.add(lambda: (os.close(master), os.close(slave)))
        writer = _TactileWriter(master, script.tactile).start()
        devices.add(writer.stop)
        tactile_port = os.ttyname(slave)
    try:
        if ft_url:
            kind, host, port = parse_ft_url(ft_url)
            cls = OnRobotHexSensor if kind == "hex" else AtiNetFTSensor
            ft = cls(host, port)
            ft.start()
            devices.add(ft.stop)
            if not args.no_tare:
                ft.tare(n_samples=100)
            sources.ft = ft.buffer
            described["ft"] = ft.device
        if tactile_port:
            tac = SerialTactileArray(tactile_port, args.tactile_baud)
            tac.start()
            devices.add(tac.stop)
            if tac.buffer.wait_newer(0, timeout=2.0) is None:
                raise DeviceError(tac.device, "no valid tactile frame within 2 s (format or baud rate?)")
            sources.tactile = tac.buffer
            described["tactile"] = tac.device
        if args.camera is not None:
            from lapwrench.drivers.camera import Camera
            from lapwrench.perception import DetectorConfig, PerceptionError, make_detector

            size = (cfg.camera.width, cfg.camera.height)
            cam = Camera(parse_camera(args.camera), loop=True, expected_size=size)
            cam.start()
            devices.add(cam.stop)
            try:
                detector = make_detector(args.detector, DetectorConfig(frame_size=size))
            except (PerceptionError, ImportError) as exc:
                raise CliError(f"instrument detector {args.detector!r}: {exc}") from exc
            worker = DetectorWorker(cam.buffer, detector).start()
            devices.add(worker.stop)
            sources.instruments = worker.buffer
            described["camera"] = cam.device
    except DeviceError as exc:
        raise CliError(f"device not ready: {exc}") from exc
    return sources, described


def run_main(args: argparse.Namespace) -> int:
    """``lapwrench run``. Returns the exit code (see the module docstring)."""
    from lapwrench import config as config_mod
    from lapwrench.robot.interface import RobotError

    try:
        cfg = config_mod.load(args.config)
    except config_mod.ConfigError as exc:
        print(f"lapwrench run: {exc}", file=sys.stderr)
        return 2
    if not args.dry_run and not args.robot_ip:
        print("lapwrench run: --robot-ip is required (or use --dry-run)", file=sys.stderr)
        return 2
    if args.duration is not None and not args.duration > 0:
        print("lapwrench run: --duration must be positive", file=sys.stderr)
        return 2
    devices = _Devices()
    logger = None
    script = DryRunScript() if args.dry_run else None
    try:
        sources, described = _open_sources(args, cfg, devices, script)
        loop, robot_desc = _build_loop(args, cfg, sources, script)
        if args.log:
            from lapwrench.hardware.log import RunLogger

            logger = RunLogger(
                args.log,
                {
                    "argv": sys.argv,
                    "robot": robot_desc,
                    "devices": described,
                    "dry_run": bool(args.dry_run),
                    "config": config_mod.to_dict(cfg),
                },
            )
            loop.logger = logger
        stop = threading.Event()
        previous = _install_sigint(stop)
        try:
            loop.start()
            print(f"lapwrench run: {robot_desc} connected; devices: {described or 'none'}", file=sys.stderr)
            stats = loop.run(args.duration, stop)
        finally:
            _restore_sigint(previous)
    except CliError as exc:
        print(f"lapwrench run: {exc}", file=sys.stderr)
        return 2
    except RobotError as exc:
        print(f"lapwrench run: robot error: {exc}", file=sys.stderr)
        return 3
    finally:
        devices.close()
        if logger is not None:
            logger.close()
    summary = {**stats.summary(), "log": args.log}
    print(json.dumps(summary))
    return 1 if stats.alarm else 0


def _build_loop(
    args: argparse.Namespace, cfg: Any, sources: Any, script: DryRunScript | None
) -> tuple[Any, str]:
    from lapwrench.controller import Controller
    from lapwrench.hardware.runner import ControlLoop, SourceAges
    from lapwrench.hardware.supervisor import SafetySupervisor, SupervisorConfig

    ctrl = Controller(cfg)
    if script is not None:
        from lapwrench.sim.robot import SimRobot
        from lapwrench.sim.scene import SceneConfig
        from lapwrench.sim.world import SimWorld

        world = SimWorld(SceneConfig.from_config(cfg))
        robot: Any = SimRobot(world, realtime=True, hand_force_H=lambda _t: script.force_H())
        desc = robot.device
    else:
        from lapwrench.hardware.franka import FrankaRobot, Payload

        robot = FrankaRobot(
            args.robot_ip,
            kind=cfg.robot.kind,
            realtime=args.realtime,
            ext_wrench_sign=args.ext_wrench_sign,
            report_external_force=not args.no_external_force,
            load=Payload.from_scope(ctrl.model.scope),
            dt=cfg.robot.dt,
        )
        desc = robot.device
    sup = SafetySupervisor(
        ctrl.model.limits,
        cfg.robot.dt,
        SupervisorConfig.from_config(
            cfg,
            cycle_budget=args.cycle_budget_us * 1e-6,
            max_consecutive_misses=args.max_misses,
            **({} if args.max_rcm_error is None else {"max_rcm_error": args.max_rcm_error}),
        ),
    )
    ages = SourceAges(ft=args.ft_max_age, tactile=args.tactile_max_age, instruments=args.camera_max_age)
    return ControlLoop(robot, ctrl, sup, sources, ages=ages), desc


def _install_sigint(stop: threading.Event) -> Any:
    """Ctrl-C requests a clean stop instead of killing the loop mid-command."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum: int, frame: Any) -> None:
        stop.set()

    return signal.signal(signal.SIGINT, handler)


def _restore_sigint(previous: Any) -> None:
    if previous is not None:
        signal.signal(signal.SIGINT, previous)


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
