"""The ``lapwrench ui`` command: the browser page on http://127.0.0.1:8080 by default.

Wired into the main command line by :func:`add_ui_parser`; ``python -m lapwrench.ui.cli`` runs it
alone. A bad argument (port in use, an address that cannot be bound, a bad configuration) ends with
one line ``lapwrench ui: ...`` on stderr and exit code 2, before anything is simulated.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
from typing import Any

from lapwrench import config as config_mod
from lapwrench.cli_types import (
    FOXGLOVE_DEFAULT,
    ArgumentParser,
    float_in,
    host_address,
    host_port,
    int_in,
    listen_problem,
)

MAX_SEED = 2**32 - 1
DETECTOR_CHOICES = ("projected", "shipped")  # lapwrench.ui.session.DETECTORS, without importing the sim here


class UiUsageError(Exception):
    """A bad argument of ``lapwrench ui``: one line on stderr, exit code 2."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--host", type=host_address, default="127.0.0.1", help="address to listen on (default 127.0.0.1)")
    p.add_argument("--port", type=int_in(0, 65535), default=8080, help="port to listen on (default 8080; 0: any free)")
    p.add_argument("--config", default=None, help="YAML configuration file or preset name (default: the paper's)")
    p.add_argument("--seed", type=int_in(0, MAX_SEED), default=0, help="seed of the simulated sensors' noise")
    p.add_argument("--detector", choices=DETECTOR_CHOICES, default="projected",
                   help="instrument detector: projected simulator geometry (cheap, default) or the shipped YOLO model "
                        "on rendered frames (slower than real time on a small machine)")
    p.add_argument("--view-fps", type=float_in(0.0, 60.0, lo_open=True), default=25.0,
                   help="frame rate of the laparoscope view on the page (default 25)")
    p.add_argument("--foxglove", nargs="?", const=host_port(FOXGLOVE_DEFAULT), type=host_port, default=None,
                   metavar="HOST:PORT", help=f"also serve the run live to Foxglove (default {FOXGLOVE_DEFAULT})")


def add_ui_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Add the ``ui`` command to ``lapwrench``'s subparsers (its ``func`` is :func:`ui_main`)."""
    p = subparsers.add_parser("ui", help="a browser page to guide the simulated scope by hand, live (viser)")
    add_arguments(p)
    p.set_defaults(func=ui_main)
    return p


def check_address(host: str, port: int) -> None:
    """UiUsageError if ``host:port`` cannot be listened on (in use, not a local address, unresolvable)."""
    problem = listen_problem(host, port)
    if problem:
        raise UiUsageError(f"--host/--port {problem}")


def _load(path: str | None) -> config_mod.Config:
    try:
        return config_mod.load(path)
    except config_mod.ConfigError as exc:
        raise UiUsageError(f"--config: {exc}") from exc


def ui_main(args: argparse.Namespace) -> int:
    """Run the page until Ctrl-C. Returns the exit code (2: a bad argument)."""
    try:
        cfg = _load(args.config)
        check_address(args.host, args.port)
        try:
            import viser  # noqa: F401 - checked before the world is built
        except ImportError as exc:
            raise UiUsageError("the browser UI needs the viser package (pip install viser)") from exc
    except UiUsageError as exc:
        print(f"lapwrench ui: {exc}", file=sys.stderr)
        return 2
    os.environ.setdefault("MUJOCO_GL", "egl")
    from lapwrench.ui.app import UiApp, UiOptions

    opts = UiOptions(host=args.host, port=args.port, seed=args.seed, detector=args.detector, view_fps=args.view_fps)
    with contextlib.ExitStack() as stack:
        if getattr(args, "foxglove", None) is not None:  # every loop the page builds is streamed
            from lapwrench.hardware.log.live import LiveError
            from lapwrench.hardware.log.live_sim import live_simulation
            from lapwrench.hardware.log.telemetry import simulation_layout

            try:
                layout = simulation_layout(cfg.cues)  # then every registered cue type, by its name
                stack.enter_context(live_simulation(args.foxglove, cfg.robot.kind, "lapwrench ui", layout))
            except LiveError as exc:
                print(f"lapwrench ui: --foxglove {exc}", file=sys.stderr)
                return 2
        try:
            app = UiApp(cfg, opts)
        except OSError as exc:  # the port was taken between the check and the start
            print(f"lapwrench ui: --host/--port {args.host}:{args.port}: {exc.strerror or exc}", file=sys.stderr)
            return 2
        print(f"lapwrench ui: serving {app.url} (Ctrl-C to stop)", flush=True)
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):  # also when the shell left SIGINT ignored
            signal.signal(sig, lambda *_: app.request_stop())
        app.run_forever()
    s = app.stats()
    print(f"lapwrench ui: stopped at t = {s['sim_time']:.1f} s simulated; last real-time factor {s['rtf']:.2f}")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m lapwrench.ui.cli``: the ``ui`` command alone."""
    p = ArgumentParser(prog="lapwrench ui", description=__doc__.splitlines()[0])
    add_arguments(p)
    return ui_main(p.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
