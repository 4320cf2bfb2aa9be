"""``lapwrench run`` (default): the loop in its own real-time process (:mod:`lapwrench.hardware.rt`),
the detector in another (:mod:`lapwrench.hardware.detector_process`); this process feeds, logs
and waits."""

from __future__ import annotations

import argparse
import functools
import math
import sys
import time
from collections.abc import Callable
from typing import Any

from lapwrench.hardware.devices import (
    CliError,
    Devices,
    DryRunScript,
    _simulated_devices,
    open_registered_inputs,
    parse_camera,
    parse_ft_url,
)
from lapwrench.hardware.run_common import (
    StopSignals,
    _error_exit,
    open_logger,
    print_summary,
    run_signalled,
    stop_reason,
)


def run_process(args: argparse.Namespace, cfg: Any) -> int:
    """The loop in its own process, the detector in another; this one feeds, logs and waits.
    SIGINT, SIGTERM and SIGHUP: see :mod:`lapwrench.hardware.run_common`."""
    return run_signalled(_run_process_signalled, args, cfg)


def _run_process_signalled(args: argparse.Namespace, cfg: Any, signals: StopSignals) -> int:
    from lapwrench import config as config_mod
    from lapwrench.drivers import DeviceError, SerialTactileArray
    from lapwrench.hardware.rt import FtSpec, RtOptions, RtProcess, RtSpec
    from lapwrench.hardware.runner import SourceAges
    from lapwrench.robot.errors import RobotError
    from lapwrench.safety.supervisor import SupervisorConfig

    frankysim = bool(getattr(args, "frankysim", False))
    simulated = bool(args.dry_run or frankysim)
    devices = Devices()
    logger = None
    # the script's clock starts when the loop does: until then the handle is untouched (F/T tare)
    script = DryRunScript(t0=math.inf) if simulated else None
    try:
        fake_ft = None
        if script is None:
            ft_url, tactile_port = args.ft, args.tactile
        else:
            ft_url, tactile_port, fake_ft = _simulated_devices(
                devices, script, getattr(args, "tactile_frame_format", None)
            )
        described: dict[str, str] = {}
        tactile = None
        try:
            if tactile_port:
                tac = SerialTactileArray(tactile_port, args.tactile_baud, getattr(args, "tactile_frame_format", None))
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
        registered = open_registered_inputs(cfg, devices, described)  # plugin inputs' drivers, here
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
            log_cycles=bool(args.log or args.foxglove),
            rt=RtOptions(fifo_priority=args.rt_priority or None, cpus=_cpus(args.rt_cpus), warn=False),  # printed below
            feeder_timeout=args.feeder_timeout,
            detector_timeout=args.detector_timeout,
            script=script,
            inputs=tuple((name, s.shape, s.max_age) for name, (s, _) in registered.items()),
        )
        child_timeout = args.child_timeout or (5.0 if simulated else 0.5)
        rp = RtProcess(spec, tactile=tactile, inputs={n: b for n, (_, b) in registered.items()},
                       child_timeout=child_timeout)
        devices.add(rp.close)
        camera = _start_camera_and_detector(args, cfg, devices, rp, described) if args.camera is not None else None
        ready = rp.start()
        described.update(ready.get("devices", {}))
        for problem in ready.get("rt_problems", []):
            print(f"lapwrench run: warning: {problem}", file=sys.stderr)
        logger = open_logger(
            args, cfg,
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
        if logger is not None:
            rp.set_logger(logger)
        stop = signals.arm()  # from here on a signal asks for the stop to rest
        print(f"lapwrench run: {ready.get('robot')} ready; devices: {described or 'none'}", file=sys.stderr)
        t0 = time.monotonic()
        if camera is not None and logger is not None:  # the laparoscope view in the log and the live view
            from lapwrench.hardware.log.live import FrameTap

            devices.add(FrameTap(camera.buffer, logger, cfg, t0).close)
        if script is not None:
            script.t0 = t0
        if fake_ft is not None:
            fake_ft.set_t0(t0)
        result = rp.run(args.duration, stop, script_t0=None if script is None else t0)
    except (CliError, RobotError) as exc:
        return _error_exit(exc)
    finally:
        signals.closing()  # the log is finalized whatever arrives now
        devices.close()
        if logger is not None:
            logger.close()
    stats, report = result.stats, result.report
    summary = {
        **stats.summary(),
        "stop_reason": stop_reason(signals.stop, stats, report.get("stop_signal")),
        "log": args.log,
        "process": "rt",
        "ft_fresh_pct": round(100.0 * report["ft_fresh_cycles"] / max(1, report["hook_cycles"]), 3)
        if ft_spec is not None
        else None,
        "log_dropped_records": report.get("log_dropped"),
    }
    print_summary(summary)
    return 1 if stats.alarm else 0


def _robot_factory(args: argparse.Namespace, cfg: Any, simulated: bool) -> Callable[..., Any]:
    from lapwrench.hardware.rt import franka_factory, sim_factory

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


def _start_camera_and_detector(
    args: argparse.Namespace, cfg: Any, devices: Devices, rp: Any, described: dict[str, str]
) -> Any:
    """The camera here, its detector in its own process writing into the loop's bus; returns the camera."""
    from lapwrench.drivers import DeviceError
    from lapwrench.drivers.camera import Camera
    from lapwrench.hardware.detector_process import DetectorProcess, spec_factory
    from lapwrench.hardware.rt import RtProcessError

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
    return cam


def _cpus(text: str | None) -> tuple[int, ...] | None:
    if text is None or text == "":
        return None
    try:
        return tuple(int(c) for c in text.split(","))
    except ValueError as exc:
        raise CliError(f"CPU list must be comma-separated integers, got {text!r}") from exc
