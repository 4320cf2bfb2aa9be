"""``lapwrench demo``: run the paper's experiments headless and write a report folder.

Folder contents: ``report.md`` (one page, each result beside the paper's), ``metrics.json``,
PNG plots, MP4s of the laparoscope view, and ``configs/<scenario>.yaml`` with the seed in the
metrics. Every input is checked before the first simulation step; a run that goes unstable
stops with a message naming the time and the quantity, and leaves ``FAILED.txt`` instead of a
report.
"""

from __future__ import annotations

import contextlib
import os
import platform
import signal
import sys
import time
import traceback
from pathlib import Path
from types import SimpleNamespace

import mujoco

from lapwrench import __version__
from lapwrench import config as config_mod
from lapwrench.controller import check_explicit_step_at_home
from lapwrench.jit import cache_is_warm
from lapwrench.robot_kinds import ROBOT_KINDS, unknown_kind_message
from lapwrench.sim import report
from lapwrench.sim.demo_tasks import (
    PRINTED_DAMPING,
    TRACKING_SCENARIOS,
    DemoError,
    DemoInterrupted,
    DemoPlan,
    StopSignals,
    run_tasks,
    stop_signals,
)
from lapwrench.sim.results import ScenarioResult, number
from lapwrench.sim.scenarios import FRANKA_TUNED, SCENARIOS, SIM_SECONDS, scenarios_for
from lapwrench.sim.world import CONTROL_DT

MAX_SEED = 2**32 - 1  # numpy's legacy seeding takes 32 bits

def plan_demo(
    out: str | Path,
    scenarios: list[str] | None = None,
    config: str | None = None,
    tracking_config: str | None = None,
    seed: int = 0,
    time_scale: float = 1.0,
    video: bool = True,
    printed_damping_check: bool = True,
    detector: str = "shipped",
    workers: int | None = None,
    robot: str | None = None,
) -> DemoPlan:
    """Validate everything (names, numbers, robot, configs, the detector's model, output folder) and
    return the plan. Nothing is simulated, written or deleted before every check has passed. ``robot``
    (a shipped arm's name) overrides the configs' ``robot.kind``; without ``scenarios`` a simulation-only
    arm runs all but the Franka-tuned ones (:func:`~lapwrench.sim.scenarios.scenarios_for`)."""
    if workers is None:
        workers = min(4, os.cpu_count() or 1)
    if isinstance(workers, bool) or not isinstance(workers, int) or not 1 <= workers <= 64:
        raise DemoError(f"workers must be a whole number from 1 to 64, got {workers!r}")
    if isinstance(seed, bool) or not isinstance(seed, int) or not 0 <= seed <= MAX_SEED:
        raise DemoError(f"seed must be a whole number from 0 to {MAX_SEED}, got {str(seed)[:60]}")
    if robot is not None and robot not in ROBOT_KINDS:
        raise DemoError(f"--robot {unknown_kind_message(str(robot))}")
    names = tuple(scenarios or SCENARIOS)
    unknown = [n for n in names if n not in SCENARIOS]
    if unknown:
        what = ", ".join(repr(n[:60]) if n.strip() else "'' (an empty name)" for n in unknown)
        raise DemoError(f"unknown scenario {what}; choose from {', '.join(SCENARIOS)} (separated by spaces)")
    if detector not in ("shipped", "classical", "projected") and not Path(detector).is_file():
        raise DemoError(
            f"detector must be shipped, classical, projected or a model file; {detector[:60]!r} "
            f"{'is not a file' if Path(detector).exists() else 'not found'}"
        )
    if detector == "shipped":
        from lapwrench.perception import SHIPPED_MODEL

        if not SHIPPED_MODEL.is_file():
            raise DemoError(f"the shipped detector model is missing: {SHIPPED_MODEL}")
    if not (0.05 <= time_scale <= 1.0):
        raise DemoError(f"time scale must lie in [0.05, 1], got {time_scale}")
    try:
        base = config_mod.load(config)
        tracking = config_mod.load(tracking_config or config)
        if robot is not None:
            base, tracking = (c.replace(robot={"kind": robot}) for c in (base, tracking))
    except config_mod.ConfigError as exc:
        raise DemoError(str(exc)) from exc
    kind = base.robot.kind
    skipped: tuple[str, ...] = ()
    if tracking.robot.kind != kind:
        raise DemoError(f"the configs name two robots ({kind}, {tracking.robot.kind}); use --robot to pick one")
    if not scenarios:
        names = scenarios_for(kind)
        skipped = tuple(n for n in SCENARIOS if n not in names)
    elif tuned := [n for n in names if n in FRANKA_TUNED and n not in scenarios_for(kind)]:
        raise DemoError(f"scenario {', '.join(tuned)} is tuned for the Franka arms; {kind} runs "
                        f"{', '.join(scenarios_for(kind))}")
    for c in (base, tracking):
        if c.robot.control_rate_hz != 1.0 / CONTROL_DT:
            raise DemoError(
                f"robot.control_rate_hz must be {1.0 / CONTROL_DT:.0f} (the simulated Franka runs at 1 kHz), "
                f"got {c.robot.control_rate_hz}"
            )
    try:
        for c in (base, tracking):  # refused at each scenario's start as well; said here, before any
            check_explicit_step_at_home(c)
    except config_mod.ConfigError as exc:
        raise DemoError(str(exc)) from exc
    check_detector(detector, tracking)
    try:
        out = config_mod.ensure_writable_dir(out)
    except OSError as exc:
        raise DemoError(f"report folder {out} is not writable: {exc}") from exc
    configs, sources = {}, {}
    for n in names:
        use_tracking = n in TRACKING_SCENARIOS
        configs[n] = tracking if use_tracking else base
        sources[n] = (tracking_config or config or "defaults") if use_tracking else (config or "defaults")
    return DemoPlan(
        out,
        names,
        configs,
        sources,
        seed,
        time_scale,
        video,
        printed_damping_check and config is None and any(n in TRACKING_SCENARIOS for n in names),
        detector,
        workers,
        skipped,
    )


def check_detector(spec: str, cfg: config_mod.Config) -> None:
    """Load the detector now, through the factory the scenarios use, whatever scenarios run: a bad
    model is refused here, before anything is simulated or the folder's previous report is touched,
    not when a tracking scenario starts minutes later."""
    if spec == "projected":
        return
    from lapwrench.perception import PerceptionError
    from lapwrench.sim.detectors import make_detector

    try:
        make_detector(spec, SimpleNamespace(n_instruments=1), cfg)  # type: ignore[arg-type]
    except (PerceptionError, ImportError, OSError, ValueError) as exc:
        detail = " ".join(str(exc).split())
        detail = detail if len(detail) <= 240 else detail[:237] + "..."
        raise DemoError(f"detector {spec[:60]!r} cannot be used: {detail}") from exc


def run_demo(plan: DemoPlan, progress: bool = True) -> dict[str, ScenarioResult]:
    """Run ``plan`` and write its report; returns the results by scenario.

    Raises:
        DemoError: a scenario failed (``FAILED.txt`` says why).
        KeyboardInterrupt: Ctrl-C, SIGTERM or SIGHUP (:class:`DemoInterrupted`, from the main thread):
            the workers are stopped and ``FAILED.txt`` written.
    """
    with stop_signals() as signals:
        return _run_demo(plan, progress, signals)


def _run_demo(plan: DemoPlan, progress: bool, signals: StopSignals) -> dict[str, ScenarioResult]:
    from tqdm import tqdm

    out = plan.out
    try:
        for stale in ("report.md", "metrics.json", "FAILED.txt"):
            (out / stale).unlink(missing_ok=True)
        (out / "configs").mkdir(exist_ok=True)
        for name, cfg in plan.configs.items():
            config_mod.dump(cfg, out / "configs" / f"{name}.yaml")
    except KeyboardInterrupt as exc:  # the previous report may be gone already: say why
        _write_failed(out, exc)
        raise
    total = sum(SIM_SECONDS[n] for n in plan.scenarios) * plan.time_scale
    if plan.printed_damping_check:
        total += SIM_SECONDS["needle-search"] * plan.time_scale  # the check is a needle search
    bar = tqdm(
        total=round(total, 1),
        unit="sim s",
        desc="lapwrench demo",
        disable=not progress,
        mininterval=1.0,
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} sim s [{elapsed}<{remaining}{postfix}]",
    )
    if progress and not cache_is_warm():
        bar.write("lapwrench demo: the first run of this version compiles the control kernels before the first "
                  "simulated second (a few minutes; cached for the next runs)", file=sys.stderr)
    t0 = time.perf_counter()
    names = list(plan.scenarios) + ([PRINTED_DAMPING] if plan.printed_damping_check else [])
    try:
        done = run_tasks(plan, names, bar)
    except (DemoError, KeyboardInterrupt) as exc:
        bar.close()
        if signals.signum is not None and not isinstance(exc, KeyboardInterrupt):  # a worker the signal ended
            exc = DemoInterrupted(signals.signum)
        _write_failed(out, exc)
        raise exc
    bar.update(max(0.0, bar.total - bar.n))
    bar.close()
    results: dict[str, ScenarioResult] = {}
    for n in plan.scenarios:
        r = done[n]
        assert isinstance(r, ScenarioResult)  # a scenario's; the printed-damping check alone gives a text
        results[n] = r
    figures = {n: r.figures for n, r in results.items()}  # drawn by the tasks (run_tasks)
    check = done.get(PRINTED_DAMPING)
    wall = time.perf_counter() - t0
    meta = {
        "lapwrench": __version__,
        "mujoco": mujoco.__version__,
        "python": platform.python_version(),
        "seed": plan.seed,
        "time_scale": plan.time_scale,
        "robot": plan.robot,
        "physics_dt_ms": 0.5,
        "config_sources": plan.config_sources,
        "wall_s": wall,
        "workers": plan.workers,
        "sim_s": sum(sum(number(r.metrics, "duration_s") for r in res.runs) for res in results.values()),
        "instrument_source": _instrument_sources(results),
        "printed_damping_check": check,
        "notes": report.demo_notes(plan.time_scale, plan.robot, plan.skipped),
    }
    report.write_metrics(out, results, meta)
    report.write_report(out, results, meta, figures)
    return results


def _write_failed(out: Path, exc: BaseException) -> None:
    """``FAILED.txt``: why the run stopped (and where, for an unexpected exception), in place of the
    report the run deleted at its start."""
    if isinstance(exc, DemoInterrupted) and exc.signum != signal.SIGINT:
        text = f"stopped by {exc.name}; no report was written"
    elif isinstance(exc, KeyboardInterrupt):
        text = "interrupted (Ctrl-C); no report was written"
    else:
        text = str(exc)
    cause = exc.__cause__
    if cause is not None:
        text += "\n\n" + "".join(traceback.format_exception(cause))
    with contextlib.suppress(OSError):
        (out / "FAILED.txt").write_text(text + "\n")


def _instrument_sources(results: dict[str, ScenarioResult]) -> str:
    sources = [f"{name}: {r.instrument_source}" for name, r in results.items() if r.instrument_source]
    return "; ".join(sources) or "none (no tracking scenario run)"
