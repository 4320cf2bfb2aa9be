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
(:mod:`lapwrench.hardware.rt_process`) with the robot, the controller, the supervisor and the F/T
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

Exit codes: 0 clean run, 1 the supervisor raised an alarm, 2 a device or argument error, 3 a robot
error (including the real-time process dying or hanging).
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import math
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


def _run_in_process(args: argparse.Namespace, cfg: Any) -> int:
    """The former single-process loop (``--in-process``): sensor and detector threads share the GIL."""
    from lapwrench import config as config_mod
    from lapwrench.robot.interface import RobotError

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
                    "process": "in-process",
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
    summary = {**stats.summary(), "log": args.log, "process": "in-process"}
    print(json.dumps(summary))
    return 1 if stats.alarm else 0


def _cpus(text: str | None) -> tuple[int, ...] | None:
    if text is None or text == "":
        return None
    try:
        return tuple(int(c) for c in text.split(","))
    except ValueError as exc:
        raise CliError(f"CPU list must be comma-separated integers, got {text!r}") from exc


def _force_counts(force_fn: Callable[[float], Any], t0: Any, _i: int) -> np.ndarray:
    f = np.asarray(force_fn(time.monotonic() - t0.value), dtype=float)
    return np.concatenate([f * 10000.0, np.zeros(3)]).round()


def _fake_ft_main(
    force_fn: Callable[[float], Any], t0: Any, rate_hz: float, conn: Any, fifo_priority: int | None = None
) -> None:
    import multiprocessing as mp

    from lapwrench.drivers.fakes import FakeFTDevice

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if fifo_priority:  # it stands for a device with a CPU of its own: keep it off our CPU contention
        with contextlib.suppress(OSError, AttributeError):
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(fifo_priority))
    dev = FakeFTDevice(rate_hz=rate_hz, counts_fn=functools.partial(_force_counts, force_fn, t0)).start()
    try:
        conn.send(dev.port)
        parent = mp.parent_process()
        while not conn.poll(0.1):
            if parent is not None and not parent.is_alive():
                break
    finally:
        dev.close()


class FakeFTProcess:
    """A simulated OnRobot HEX box (:class:`~lapwrench.drivers.fakes.FakeFTDevice`, 10000 counts/N) in
    its own process, streaming ``force_fn(t)`` (N, in {H}) at ``rate_hz`` on 127.0.0.1; ``t`` counts
    from :meth:`set_t0` (before it, ``-inf``). A real box does not share this process's interpreter,
    so neither does this one (its sends are not delayed by this process's threads). ``fifo_priority``
    (when permitted) keeps the simulated box off our own CPU contention, as a real box has its own CPU."""

    def __init__(
        self, force_fn: Callable[[float], Any], rate_hz: float = 1000.0, fifo_priority: int | None = None
    ) -> None:
        import multiprocessing as mp

        self.ctx = mp.get_context("spawn")
        self.t0 = self.ctx.RawValue("d", math.inf)
        self.force_fn = force_fn
        self.rate_hz = rate_hz
        self.fifo_priority = fifo_priority
        self.proc: Any = None
        self.port = 0
        self._conn: Any = None

    def start(self, timeout: float = 30.0) -> FakeFTProcess:
        self._conn, child = self.ctx.Pipe()
        self.proc = self.ctx.Process(
            target=_fake_ft_main,
            args=(self.force_fn, self.t0, self.rate_hz, child, self.fifo_priority),
            name="lapwrench-fake-ft",
            daemon=True,
        )
        self.proc.start()
        child.close()
        if not self._conn.poll(timeout):
            self.close()
            raise CliError("the simulated F/T box did not start")
        self.port = int(self._conn.recv())
        return self

    def set_t0(self, t0: float) -> None:
        self.t0.value = t0

    def close(self) -> None:
        if self.proc is None:
            return
        with contextlib.suppress(Exception):
            self._conn.send("stop")
        self.proc.join(3.0)
        if self.proc.exitcode is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(self.proc.pid, signal.SIGKILL)
            self.proc.join(2.0)
        with contextlib.suppress(Exception):
            self._conn.close()
        self.proc = None


def _simulated_devices(devices: _Devices, script: DryRunScript) -> tuple[str, str, FakeFTProcess]:
    """The dry run's F/T box (loopback UDP, own process) and tactile array (a pty)."""
    fake = FakeFTProcess(script.force_H).start()
    devices.add(fake.close)
    master, slave = os.openpty()
    devices.add(lambda: (os.close(master), os.close(slave)))
    writer = _TactileWriter(master, script.tactile).start()
    devices.add(writer.stop)
    return f"hex://127.0.0.1:{fake.port}", os.ttyname(slave), fake


def _robot_factory(args: argparse.Namespace, cfg: Any, simulated: bool) -> Callable[..., Any]:
    from lapwrench.hardware.rt_process import franka_factory, sim_factory

    if getattr(args, "frankysim", False):
        return functools.partial(
            franka_factory, robot_ip="127.0.0.1", kind="fr3", realtime="ignore", report_external_force=False
        )
    if simulated:
        return functools.partial(sim_factory, realtime=True)
    return functools.partial(
        franka_factory,
        robot_ip=args.robot_ip,
        kind=cfg.robot.kind,
        realtime=args.realtime,
        ext_wrench_sign=args.ext_wrench_sign,
        report_external_force=not args.no_external_force,
    )


def _run_process(args: argparse.Namespace, cfg: Any) -> int:
    """The loop in its own process, the detector in another; this one feeds, logs and waits."""
    from lapwrench import config as config_mod
    from lapwrench.drivers import DeviceError, SerialTactileArray
    from lapwrench.hardware.rt_process import FtSpec, RtOptions, RtProcess, RtProcessError, RtSpec
    from lapwrench.hardware.runner import SourceAges
    from lapwrench.hardware.supervisor import SupervisorConfig
    from lapwrench.robot.interface import RobotError

    frankysim = bool(getattr(args, "frankysim", False))
    simulated = bool(args.dry_run or frankysim)
    devices = _Devices()
    logger = None
    # the script's clock starts when the loop does: until then the handle is untouched (F/T tare)
    script = DryRunScript(t0=math.inf) if simulated else None
    try:
        fake_ft = None
        if script is None:
            ft_url, tactile_port = args.ft, args.tactile
        else:
            ft_url, tactile_port, fake_ft = _simulated_devices(devices, script)
        described: dict[str, str] = {}
        tactile = None
        try:
            if tactile_port:
                tac = SerialTactileArray(tactile_port, args.tactile_baud)
                tac.start()
                devices.add(tac.stop)
                if tac.buffer.wait_newer(0, timeout=2.0) is None:
                    raise DeviceError(tac.device, "no valid tactile frame within 2 s (format or baud rate?)")
                tactile = tac.buffer
                described["tactile"] = tac.device
        except DeviceError as exc:
            raise CliError(f"device not ready: {exc}") from exc
        ft_spec = None
        if ft_url:
            kind, host, port = parse_ft_url(ft_url)
            ft_spec = FtSpec(kind, host, port, tare=not args.no_tare)
        if frankysim:
            from lapwrench.hardware.frankysim import FrankySimServer, frankysim_available
            from lapwrench.virtual import DEFAULT_Q0

            missing = frankysim_available()
            if missing:
                raise CliError(f"--frankysim: franky-sim/pylibfranka unavailable: {missing}")
            server = FrankySimServer(DEFAULT_Q0)
            devices.add(server.stop)
            server.start()
        sup_cfg = SupervisorConfig.from_config(
            cfg,
            cycle_budget=args.cycle_budget_us * 1e-6,
            max_consecutive_misses=args.max_misses,
            **({} if args.max_rcm_error is None else {"max_rcm_error": args.max_rcm_error}),
        )
        spec = RtSpec(
            cfg=cfg,
            robot_factory=_robot_factory(args, cfg, simulated),
            supervisor=sup_cfg,
            ages=SourceAges(ft=args.ft_max_age, tactile=args.tactile_max_age, instruments=args.camera_max_age),
            ft=ft_spec,
            tactile=tactile is not None,
            instruments=args.camera is not None,
            duration=args.duration,
            log_cycles=bool(args.log),
            rt=RtOptions(fifo_priority=args.rt_priority or None, cpus=_cpus(args.rt_cpus), warn=False),  # printed below
            feeder_timeout=args.feeder_timeout,
            detector_timeout=args.detector_timeout,
            script=script,
        )
        child_timeout = args.child_timeout or (5.0 if simulated else 0.5)
        rp = RtProcess(spec, tactile=tactile, child_timeout=child_timeout)
        devices.add(rp.close)
        if args.camera is not None:
            _start_camera_and_detector(args, cfg, devices, rp, described)
        ready = rp.start()
        described.update(ready.get("devices", {}))
        for problem in ready.get("rt_problems", []):
            print(f"lapwrench run: warning: {problem}", file=sys.stderr)
        if args.log:
            from lapwrench.hardware.log import RunLogger

            logger = RunLogger(
                args.log,
                {
                    "argv": sys.argv,
                    "robot": ready.get("robot"),
                    "devices": described,
                    "dry_run": simulated,
                    "frankysim": frankysim,
                    "process": "rt",
                    "config": config_mod.to_dict(cfg),
                },
            )
            rp.set_logger(logger)
        stop = threading.Event()
        previous = _install_sigint(stop)
        try:
            print(f"lapwrench run: {ready.get('robot')} ready; devices: {described or 'none'}", file=sys.stderr)
            t0 = time.monotonic()
            if script is not None:
                script.t0 = t0
            if fake_ft is not None:
                fake_ft.set_t0(t0)
            result = rp.run(args.duration, stop, script_t0=None if script is None else t0)
        finally:
            _restore_sigint(previous)
    except CliError as exc:
        print(f"lapwrench run: {exc}", file=sys.stderr)
        return 2
    except RtProcessError as exc:
        if getattr(exc, "kind", "") == "device":
            print(f"lapwrench run: device not ready: {exc}", file=sys.stderr)
            return 2
        print(f"lapwrench run: robot error: {exc}", file=sys.stderr)
        return 3
    except RobotError as exc:
        print(f"lapwrench run: robot error: {exc}", file=sys.stderr)
        return 3
    finally:
        devices.close()
        if logger is not None:
            logger.close()
    stats, report = result.stats, result.report
    summary = {
        **stats.summary(),
        "log": args.log,
        "process": "rt",
        "ft_fresh_pct": round(100.0 * report["ft_fresh_cycles"] / max(1, report["hook_cycles"]), 3)
        if ft_spec is not None
        else None,
        "log_dropped_records": report.get("log_dropped"),
    }
    print(json.dumps(summary))
    return 1 if stats.alarm else 0


def _start_camera_and_detector(
    args: argparse.Namespace, cfg: Any, devices: _Devices, rp: Any, described: dict[str, str]
) -> None:
    """The camera here, its detector in its own process writing into the loop's bus."""
    from lapwrench.drivers import DeviceError
    from lapwrench.drivers.camera import Camera
    from lapwrench.hardware.detector_process import DetectorProcess, spec_factory
    from lapwrench.hardware.rt_process import RtProcessError

    size = (cfg.camera.width, cfg.camera.height)
    try:
        cam = Camera(parse_camera(args.camera), loop=True, expected_size=size)
        cam.start()
    except DeviceError as exc:
        raise CliError(f"device not ready: {exc}") from exc
    devices.add(cam.stop)
    det = DetectorProcess(
        functools.partial(spec_factory, args.detector, size),
        rp.bus_name,
        size,
        bus_rows=(rp.spec.log_rows, rp.spec.event_rows),
        cpus=_cpus(getattr(args, "detector_cpus", None)),
    )
    devices.add(det.stop)
    try:
        det.start()
    except RtProcessError as exc:
        raise CliError(f"instrument detector {args.detector!r}: {exc}") from exc
    det.forward(cam.buffer)
    rp.detector_pid = det.pid
    described["camera"] = cam.device


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
    """Ctrl-C and SIGTERM request a clean stop to rest instead of killing the loop mid-command."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum: int, frame: Any) -> None:
        stop.set()

    return {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}


def _restore_sigint(previous: Any) -> None:
    if previous is not None:
        for sig, h in previous.items():
            signal.signal(sig, h)


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
