"""``lapwrench run --in-process``: the former single-process loop, for debugging (the sensor and
detector threads share the GIL with the loop)."""

from __future__ import annotations

import argparse
import math
import sys
import time
from typing import Any

from lapwrench.hardware.devices import CliError, Devices, DryRunScript, open_sources
from lapwrench.hardware.run_common import (
    StopSignals,
    _error_exit,
    open_logger,
    print_summary,
    run_signalled,
    stop_reason,
)


def run_in_process(args: argparse.Namespace, cfg: Any) -> int:
    """The former single-process loop (``--in-process``): sensor and detector threads share the GIL.
    SIGINT, SIGTERM and SIGHUP: see :mod:`lapwrench.hardware.run_common`."""
    return run_signalled(_run_in_process_signalled, args, cfg)


def _run_in_process_signalled(args: argparse.Namespace, cfg: Any, signals: StopSignals) -> int:
    from lapwrench import config as config_mod
    from lapwrench.robot.errors import RobotError

    devices = Devices()
    logger = None
    # the script's clock starts when the loop does (as in the process path): until then the handle
    # is untouched (F/T tare), and a slow start-up does not play the pushes to nobody
    script = DryRunScript(t0=math.inf) if args.dry_run else None
    try:
        sources, described = open_sources(args, cfg, devices, script)
        loop, robot_desc = _build_loop(args, cfg, sources, script)
        logger = open_logger(
            args, cfg,
            {
                "argv": sys.argv,
                "robot": robot_desc,
                "devices": described,
                "dry_run": bool(args.dry_run),
                "process": "in-process",
                "config": config_mod.to_dict(cfg),
            },
        )
        if logger is not None:
            loop.logger = logger
        stop = signals.arm()  # from here on a signal asks for the stop to rest
        loop.start()
        print(f"lapwrench run: {robot_desc} connected; devices: {described or 'none'}", file=sys.stderr)
        if script is not None:
            script.t0 = time.monotonic()
        stats = loop.run(args.duration, stop)
        if logger is not None and stop.reason is not None and stop.at is not None:
            logger.event(loop.session_time(stop.at), "stop_requested", f"{stop.reason}: stopping to rest")
    except (CliError, RobotError) as exc:
        return _error_exit(exc)
    finally:
        signals.closing()  # the log is finalized whatever arrives now
        devices.close()
        if logger is not None:
            logger.close()
    summary = {
        **stats.summary(),
        "stop_reason": stop_reason(signals.stop, stats),
        "log": args.log,
        "process": "in-process",
    }
    print_summary(summary)
    return 1 if stats.alarm else 0


def _build_loop(
    args: argparse.Namespace, cfg: Any, sources: Any, script: DryRunScript | None
) -> tuple[Any, str]:
    from lapwrench.controller import Controller
    from lapwrench.hardware.runner import ControlLoop, SourceAges
    from lapwrench.safety.supervisor import SafetySupervisor, SupervisorConfig

    ctrl = Controller(cfg)
    if script is not None:
        from lapwrench.sim.robot import SimRobot
        from lapwrench.sim.scene.config import SceneConfig
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
