"""The ``lapwrench`` command line.

Its stop signals (Ctrl-C, SIGTERM, SIGHUP: one line and exit code 128 + the signal's number, from this
module's first line on) are :mod:`lapwrench.cli_signals`'.
"""

from __future__ import annotations

import os
import sys

from lapwrench.cli_signals import exit_at_once, exit_quietly, handle_stop_signals  # light imports: first


def _started_as_lapwrench() -> bool:
    """Whether this process is the ``lapwrench`` program (its console script, ``python -m lapwrench`` or
    ``python -m lapwrench.cli``), not a program that imports this module (the tests)."""
    main_module = sys.modules.get("__main__")
    spec = getattr(main_module, "__spec__", None)
    if spec is not None:
        return spec.name in ("lapwrench.__main__", "lapwrench.cli")
    return os.path.basename(getattr(main_module, "__file__", None) or "") == "lapwrench"


if _started_as_lapwrench():  # before the imports below (numpy, ...): a Ctrl-C while they load is one line
    handle_stop_signals(exit_at_once)

import argparse  # noqa: E402
import contextlib  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import select  # noqa: E402
import signal  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from lapwrench import config as config_mod  # noqa: E402
from lapwrench.cli_signals import restore, signal_of, stop_line, stop_once  # noqa: E402
from lapwrench.cli_types import (  # noqa: E402
    FOXGLOVE_DEFAULT,
    ArgumentParser,
    display_path,
    float_in,
    host_port,
    int_in,
    output_dir,
)
from lapwrench.plugins import CueError  # noqa: E402
from lapwrench.robot.errors import RobotDescriptionError  # noqa: E402

MIN_VIRTUAL_SECONDS = 0.1  # enough ticks for the metrics and the plot
# The virtual run keeps every tick in memory: 4.8 MB a second of robot time (peak RSS 404 MB at 10 s, 645 MB at
# 60 s, 2026-12-03); 3600 s took 17 GB. 600 s: 3.3 GB.
MAX_VIRTUAL_SECONDS = 600.0
MAX_SEED = 2**32 - 1  # numpy's legacy seeding takes 32 bits


class UsageError(Exception):
    """A bad argument or input file: ``lapwrench <command>: <message>`` and exit code 2."""


def _writable_dir(path: Path) -> Path:
    try:
        return config_mod.ensure_writable_dir(path)
    except OSError as exc:
        raise UsageError(f"report folder {path} is not writable: {exc.strerror or exc}") from exc


def _load_config(path: str | None) -> config_mod.Config:
    try:
        return config_mod.load(path)
    except config_mod.ConfigError as exc:
        raise UsageError(str(exc)) from exc


def cmd_virtual(args: argparse.Namespace) -> int:
    """Closed loop on the controller's own virtual dynamics: handle phase, then tracking."""
    from tqdm import tqdm

    from lapwrench.controller import Controller
    from lapwrench.virtual import HandScript, home_pose, limits_report, plot_virtual, run_virtual

    cfg = _load_config(args.config)
    out = _writable_dir(Path(args.out))
    ctrl = Controller(cfg)
    q0 = home_pose(cfg.robot.kind)
    ctrl.reset(q0)
    kin = ctrl.model.kinematics(q0, np.zeros(ctrl.model.nv))
    depth = 0.07
    # an instrument tip sliding over tissue 7 cm ahead of the camera
    centre = kin.p_C + depth * kin.d_z

    def instrument(t: float) -> np.ndarray:
        lateral = np.array([0.025 * np.sin(0.4 * t), 0.015 * np.sin(0.25 * t + 1.0), 0.0])
        return (centre + kin.R_C @ lateral)[None]

    def hand_force(t: float) -> np.ndarray:
        if 4.0 <= t < 8.0:
            return np.array([8.0, 0.0, 0.0])
        return np.array([0.0, -6.0, 0.0]) if 12.0 <= t < 15.0 else np.zeros(3)

    def grip(t: float) -> float:
        return 2.0 if 3.5 <= t < 8.5 else (1.1 if 11.5 <= t < 15.5 else 0.0)

    duration = args.duration
    if not (math.isfinite(duration) and MIN_VIRTUAL_SECONDS <= duration <= MAX_VIRTUAL_SECONDS):
        raise UsageError(
            f"--duration must be a number of seconds from {MIN_VIRTUAL_SECONDS:g} to {MAX_VIRTUAL_SECONDS:g}"
        )
    steps = round(duration / cfg.robot.dt)
    bar = tqdm(total=steps, desc="virtual closed loop", unit="tick", mininterval=0.5, disable=args.quiet)
    t0 = time.perf_counter()
    ctrl, log = run_virtual(
        cfg,
        duration,
        HandScript(force=hand_force, delta=grip),
        instrument,
        controller=ctrl,
        progress=lambda k, n: bar.update(1),
    )
    bar.close()
    wall = time.perf_counter() - t0
    err = np.array([r.rcm_error for r in log.results]) * 1e3
    modes: dict[str, float] = {}
    for r in log.results:
        modes[r.mode] = modes.get(r.mode, 0.0) + cfg.robot.dt
    usage = limits_report(ctrl, log, q0)
    metrics = {
        "duration_s": duration,
        "rcm_error_max_mm": float(err.max()),
        "rcm_error_rms_mm": float(np.sqrt(np.mean(err**2))),
        "mode_time_s": {k: round(v, 3) for k, v in modes.items()},
        "limit_usage": usage,
        "events": dict(ctrl.event_counts),
        "wall_time_s": wall,
    }
    for k in range(0, len(log.results), round(2.0 / cfg.robot.dt)):
        r = log.results[k]
        print(f"t={r.time:5.1f} s  mode={r.mode:16s} |e_R|={r.rcm_error * 1e3:7.4f} mm  delta={r.delta:.2f}")
    print(f"RCM error: max {metrics['rcm_error_max_mm']:.4f} mm, RMS {metrics['rcm_error_rms_mm']:.4f} mm")
    plot_virtual(log, cfg, out / "virtual_closed_loop.png")
    (out / "virtual_metrics.json").write_text(json.dumps(metrics, indent=2))
    config_mod.dump(cfg, out / "config.yaml")
    print(f"wrote {display_path(out / 'virtual_closed_loop.png')} and {display_path(out / 'virtual_metrics.json')}")
    return 0


def _live(
    address: tuple[str, int] | None, robot: str, command: str, configs: list[config_mod.Config]
) -> contextlib.AbstractContextManager[object]:
    """Live telemetry of the simulated runs while the block runs (nothing without an address), with the
    cue telemetry of ``configs`` (the ones the runs use) and of every registered cue type; a port
    that cannot be served is a usage error, before anything runs."""
    if address is None:
        return contextlib.nullcontext()
    from lapwrench.hardware.log.live import LiveError
    from lapwrench.hardware.log.live_sim import live_simulation
    from lapwrench.hardware.log.telemetry import simulation_layout

    try:
        return live_simulation(address, robot, f"lapwrench {command}", simulation_layout(*(c.cues for c in configs)))
    except LiveError as exc:
        raise UsageError(f"--foxglove {exc}") from exc


def cmd_demo(args: argparse.Namespace) -> int:
    """The main job: the paper's experiments in the MuJoCo world, written to a report folder."""
    os.environ.setdefault("MUJOCO_GL", "egl")
    from lapwrench.sim.demo import DemoError, plan_demo, run_demo
    from lapwrench.sim.demo_tasks import stop_signals

    try:
        with stop_signals():  # SIGTERM and SIGHUP as Ctrl-C: one line, 143 and 129
            plan = plan_demo(
                args.out,
                scenarios=args.scenarios,
                config=args.config,
                tracking_config=args.tracking_config,
                seed=args.seed,
                time_scale=args.time_scale,
                video=not args.no_video,
                detector=args.detector,
                workers=1 if args.foxglove else args.workers,  # live: the scenarios run here, one after another
                robot=args.robot,
            )
    except DemoError as exc:  # a bad argument or input file, found before anything ran
        raise UsageError(str(exc)) from exc
    except KeyboardInterrupt as exc:
        return _demo_interrupted(exc)
    try:
        with stop_signals(), _live(args.foxglove, plan.robot, "demo", list(plan.configs.values())):
            results = run_demo(plan, progress=not args.quiet)
    except DemoError as exc:  # a run that failed (FAILED.txt says why)
        print(f"lapwrench demo: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as exc:  # Ctrl-C, SIGTERM or SIGHUP (FAILED.txt says so)
        return _demo_interrupted(exc)
    for name, res in results.items():
        print(f"{name}: " + ", ".join(f"{r.label}: RCM max {r.metrics['rcm_error_max_mm']:.2f} mm" for r in res.runs))
    print(f"report: {display_path(Path(args.out) / 'report.md')}")
    return 0


def _demo_interrupted(exc: KeyboardInterrupt) -> int:
    """The demo's line for a stop signal (a ``DemoInterrupted`` names it); returns 128 + its number."""
    signum = signal_of(exc)
    print(f"{stop_line('demo', signum)}; no report was written", file=sys.stderr)
    return 128 + signum


def build_parser() -> argparse.ArgumentParser:
    p = ArgumentParser(prog="lapwrench", description="Laparoscope-holding robot control (unified wrenches).")
    sub = p.add_subparsers(dest="command", required=True)

    demo = sub.add_parser("demo", help="the main job: the paper's experiments in simulation, written to a report")
    demo.add_argument(
        "--out", type=output_dir, default="reports/latest", help="report folder (default reports/latest)"
    )
    demo.add_argument(
        "--scenarios",
        nargs="+",
        metavar="NAME",
        help="grip, rcm-disturbance, needle-search, workflow, hard-push, zoom, keep-out (default: all)",
    )
    demo.add_argument("--config", help="YAML configuration or preset for every scenario (default: the paper's)")
    demo.add_argument(
        "--robot", metavar="NAME", default=None,
        help="the simulated arm: panda (default: the config's robot.kind), fr3, ur5 or xarm7 (ur5 and xarm7 leave out"
        " hard-push, tuned for the Franka)",
    )
    demo.add_argument("--tracking-config", help="configuration for needle-search and workflow")
    demo.add_argument(
        "--foxglove", nargs="?", const=host_port(FOXGLOVE_DEFAULT), type=host_port, default=None, metavar="HOST:PORT",
        help=f"watch the runs live in Foxglove (default {FOXGLOVE_DEFAULT}; the scenarios then run one at a time)",
    )
    demo.add_argument("--seed", type=int_in(0, MAX_SEED), default=0, help="random seed (0 to 2^32-1; default 0)")
    demo.add_argument(
        "--time-scale", type=float_in(0.05, 1.0), default=1.0, help="shorten the scenarios (0.05-1; default 1)"
    )
    demo.add_argument("--no-video", action="store_true", help="skip the MP4s")
    demo.add_argument(
        "--detector",
        default="shipped",
        help="instrument detector on the rendered frames: shipped (YOLO ONNX), classical, a .onnx/.pt "
        "model, or projected (simulator geometry, no detector)",
    )
    demo.add_argument(
        "--workers", type=int_in(1, 64), default=None,
        help="processes running scenarios side by side, 1 to 64 (default: the CPU count, at most 4; 1: in this"
        " process)",
    )
    demo.add_argument("--quiet", action="store_true", help="no progress bar")

    virt = sub.add_parser("virtual", help="closed loop on the controller's own virtual dynamics (no physics)")
    virt.add_argument("--config", help="YAML configuration or preset (default: the paper's parameters)")
    virt.add_argument("--out", type=output_dir, default="reports/virtual", help="report folder")
    virt.add_argument(
        "--duration",
        type=float_in(MIN_VIRTUAL_SECONDS, MAX_VIRTUAL_SECONDS),
        default=20.0,
        help=f"seconds of robot time, {MIN_VIRTUAL_SECONDS:g} to {MAX_VIRTUAL_SECONDS:g} (default 20)",
    )
    virt.add_argument("--quiet", action="store_true", help="no progress bar")
    from lapwrench.hardware import cli as hardware_cli

    run = sub.add_parser("run", help="run the system on a Franka (or --dry-run on the simulated robot)")
    hardware_cli.add_run_arguments(run)
    run.set_defaults(func=hardware_cli.run_main)
    rep = sub.add_parser("log-report", help="turn an MCAP run log into plots")
    hardware_cli.add_log_report_arguments(rep)
    rep.set_defaults(func=hardware_cli.log_report_main)
    from lapwrench.hardware import grip_identify

    grip = sub.add_parser("identify-grip", help="fit the handle grip's mass and centre of mass from a run log")
    grip_identify.add_identify_grip_arguments(grip)
    grip.set_defaults(func=grip_identify.identify_grip_main)

    from lapwrench.perception import cli as perception_cli

    for name, helptext, add, func in (
        (
            "dataset",
            "render a labelled YOLO dataset from the simulated world",
            perception_cli.add_dataset_arguments,
            perception_cli.dataset_main,
        ),
        (
            "train",
            "train the instrument detector (needs the training extra: scripts/train_detector.sh setup)",
            perception_cli.add_train_arguments,
            perception_cli.train_main,
        ),
        (
            "calibrate",
            "camera intrinsics from checkerboard images (Zhang's method)",
            perception_cli.add_calibrate_arguments,
            perception_cli.calibrate_main,
        ),
    ):
        sp = sub.add_parser(name, help=helptext)
        add(sp)
        sp.set_defaults(func=func)
    from lapwrench.ui.cli import add_ui_parser

    add_ui_parser(sub)
    from lapwrench.study.cli import add_parsers as add_study_parsers

    add_study_parsers(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    """Parse and run one command. Bad arguments and input files end with one line on stderr and exit
    code 2 (argparse's own errors add a usage line), a stop signal with one line and 128 + its number
    (130 for Ctrl-C; see the module); never a traceback."""
    # OpenCV's own warnings (a camera index that does not open...) would add lines to our one-line errors
    os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")
    for stream in (sys.stdout, sys.stderr):  # a path's bytes that are not UTF-8 as \udcff, never an error
        with contextlib.suppress(AttributeError, ValueError, OSError):
            stream.reconfigure(errors="backslashreplace")  # type: ignore[union-attr]
    previous = handle_stop_signals(exit_at_once)  # parsing: nothing to close yet
    stopped = False
    try:
        args = build_parser().parse_args(argv)
        with stop_once() as stop:
            try:
                code = _run(args)
            except Exception:
                if stop.signum is None:
                    raise
                code = -1  # an error on the way out after a stop signal (a clean-up met what it cut short)
            finally:
                stop.cancel()  # the command is over: a signal from now on is only noted
                stopped = stop.signum is not None
            if stop.signum is not None and code != 128 + stop.signum:
                # the stop's exception swallowed on its way (a library's `except BaseException`), or the
                # signal still waiting for lapwrench's own code when the command ended, or come after it:
                # its line and code, never the exit code of a command that ran to its end
                print(stop_line(args.command, stop.signum), file=sys.stderr)
                return 128 + stop.signum
            return code
    finally:
        restore(previous)
        if stopped and _started_as_lapwrench():  # its line is out: a signal while Python exits ends it, unsaid
            handle_stop_signals(exit_quietly)


def _run(args: argparse.Namespace) -> int:
    try:
        if args.command == "demo":
            code = cmd_demo(args)
        elif args.command == "virtual":
            code = cmd_virtual(args)
        else:
            code = int(args.func(args))
        if sys.stdout is not None:
            sys.stdout.flush()  # here, not at exit: a reader gone (BrokenPipeError) is then one line below
        return code
    except (UsageError, config_mod.ConfigError, RobotDescriptionError, CueError) as exc:
        print(f"lapwrench {args.command}: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt as exc:  # a stop signal in a command without its own handling (log-report...)
        signum = signal_of(exc)
        print(stop_line(args.command, signum), file=sys.stderr)
        return 128 + signum
    except BrokenPipeError:
        if not _stdout_gone():
            raise
        # `lapwrench ... | head -1`: the reader has gone, as SIGPIPE would end a C program (128 + 13); stdout
        # on /dev/null, so that Python's own flush at exit does not fail again with a traceback
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        with contextlib.suppress(OSError):
            print(f"lapwrench {args.command}: its output was closed (the reading end of a pipe); stopped",
                  file=sys.stderr)
        return 128 + signal.SIGPIPE


def _stdout_gone() -> bool:
    """Whether stdout is a pipe whose reading end is closed (a BrokenPipeError is then about it)."""
    try:
        poll = select.poll()
        poll.register(sys.stdout.fileno(), select.POLLOUT)
        return any(events & select.POLLERR for _, events in poll.poll(0))
    except (AttributeError, OSError, ValueError):  # no stdout, or not a file
        return False


if __name__ == "__main__":
    raise SystemExit(main())
