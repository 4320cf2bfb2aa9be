"""``lapwrench demo``: run the paper's experiments headless and write a report folder.

Folder contents: ``report.md`` (one page, each result beside the paper's), ``metrics.json``,
PNG plots, MP4s of the laparoscope view, and ``configs/<scenario>.yaml`` with the seed in the
metrics. Every input is checked before the first simulation step; a run that goes unstable
stops with a message naming the time and the quantity, and leaves ``FAILED.txt`` instead of a
report.
"""

from __future__ import annotations

import contextlib
import gc
import multiprocessing as mp
import os
import platform
import signal
import time
import traceback
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path
from queue import Empty
from types import SimpleNamespace
from typing import Any

import mujoco

from lapwrench import __version__
from lapwrench import config as config_mod
from lapwrench.robot_kinds import ROBOT_KINDS, unknown_kind_message
from lapwrench.sim import cue_scenarios, report
from lapwrench.sim.loop import SafetyStopError
from lapwrench.sim.results import ScenarioOptions, ScenarioResult
from lapwrench.sim.scenarios import FRANKA_TUNED, SCENARIOS, SIM_SECONDS, needle_search, scenarios_for
from lapwrench.sim.world import CONTROL_DT, SimulationUnstableError

TRACKING_SCENARIOS = ("needle-search", "workflow")
MAX_SEED = 2**32 - 1  # numpy's legacy seeding takes 32 bits


class DemoError(RuntimeError):
    """A bad demo input, reported before any simulation starts."""


@dataclass(frozen=True)
class DemoPlan:
    out: Path
    scenarios: tuple[str, ...]
    configs: dict[str, config_mod.Config]
    config_sources: dict[str, str]
    seed: int
    time_scale: float
    video: bool
    printed_damping_check: bool
    detector: str = "shipped"
    workers: int = 1  # scenarios run on this many processes (each scenario is seeded: same results)
    skipped: tuple[str, ...] = ()  # scenarios left out by default on this arm (tuned for the Franka)

    @property
    def robot(self) -> str:  # the arm every scenario runs on (the configs' robot.kind)
        return next(iter(self.configs.values())).robot.kind


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
        raise DemoError(f"unknown scenario {', '.join(n[:60] for n in unknown)}; choose from {', '.join(SCENARIOS)}")
    if detector not in ("shipped", "classical", "projected") and not Path(detector).is_file():
        raise DemoError(
            f"detector must be shipped, classical, projected or a model file; {detector[:60]!r} not found"
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
    kind, skipped = base.robot.kind, ()
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
    _check_detector(detector, tracking)
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


def _check_detector(spec: str, cfg: config_mod.Config) -> None:
    """Load the detector now, through the factory the scenarios use, whatever scenarios run: a bad
    model is refused here, before anything is simulated or the folder's previous report is touched,
    not when a tracking scenario starts minutes later."""
    if spec == "projected":
        return
    from lapwrench.perception import PerceptionError
    from lapwrench.sim.loop import make_detector

    try:
        make_detector(spec, SimpleNamespace(n_instruments=1), cfg)  # type: ignore[arg-type]
    except (PerceptionError, ImportError, OSError, ValueError) as exc:
        detail = " ".join(str(exc).split())
        detail = detail if len(detail) <= 240 else detail[:237] + "..."
        raise DemoError(f"detector {spec[:60]!r} cannot be used: {detail}") from exc


PRINTED_DAMPING = "needle-search, printed damping"


def _init_worker(queue: Any) -> None:
    global _PROGRESS
    _PROGRESS = queue
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the main process's to handle


_PROGRESS: Any = None


def _task(name: str, plan: DemoPlan) -> tuple[str, ScenarioResult | str, str | None]:
    """One scenario (or the printed-damping check) in a worker: (name, result or check text, error)."""

    def progress(dt: float) -> None:
        if _PROGRESS is not None:
            _PROGRESS.put(dt)

    opts = ScenarioOptions(
        seed=plan.seed,
        time_scale=plan.time_scale,
        progress=progress,
        video_dir=plan.out if plan.video and name in TRACKING_SCENARIOS else None,
        detector=plan.detector,
    )
    # The runs keep millions of small objects (the per-tick traces) and make no reference cycles:
    # the cyclic garbage collector would only scan them, in pauses of several ms inside the loop.
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        if name == PRINTED_DAMPING:
            return name, _printed_damping_check(opts, plan.robot), None
        return name, SCENARIOS[name](plan.configs[name], opts), None
    except (SimulationUnstableError, SafetyStopError) as exc:
        return name, "", f"simulation of '{name}' stopped: {exc}. No report was written."
    finally:
        if gc_was_enabled:
            gc.enable()


def _run_tasks(plan: DemoPlan, names: list[str], bar: Any) -> dict[str, ScenarioResult | str]:
    """Run the tasks on ``plan.workers`` processes (longest first), or in this process with one worker."""
    global _PROGRESS
    out: dict[str, ScenarioResult | str] = {}
    if plan.workers <= 1:
        _PROGRESS = _BarFeed(bar)
        try:
            for name in names:
                bar.set_postfix_str(name)
                try:
                    _, res, err = _task(name, plan)
                except Exception as exc:  # as from a worker: one line, FAILED.txt (with the traceback)
                    raise DemoError(f"scenario '{name}' failed: {type(exc).__name__}: {exc}") from exc
                if err:
                    raise DemoError(err)
                out[name] = res
        finally:
            _PROGRESS = None
        return out
    from lapwrench.controller import Controller

    Controller(plan.configs[names[0]] if names[0] in plan.configs else config_mod.load())  # compile once, here:
    # the workers then load numba's cache instead of each compiling the tick (a minute on a fresh clone)
    ctx = mp.get_context("spawn")  # no fork of a process holding MuJoCo/EGL and numba state
    queue = ctx.Queue()
    pool = ProcessPoolExecutor(plan.workers, mp_context=ctx, initializer=_init_worker, initargs=(queue,))
    try:
        return _collect(pool, plan, names, queue, bar, out)
    except BaseException:  # Ctrl-C or a failed scenario: stop the other workers now, not at their end
        for proc in list(getattr(pool, "_processes", {}).values()):
            proc.terminate()
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    finally:
        pool.shutdown(wait=True)


def _collect(
    pool: ProcessPoolExecutor, plan: DemoPlan, names: list[str], queue: Any, bar: Any,
    out: dict[str, ScenarioResult | str],
) -> dict[str, ScenarioResult | str]:
    """Submit the tasks longest first and gather their results, feeding the progress bar."""
    order = sorted(names, key=lambda n: -SIM_SECONDS.get(n, 15.0))
    names_of = {pool.submit(_task, n, plan): n for n in order}
    pending = set(names_of)
    bar.set_postfix_str(f"{plan.workers} workers")
    while pending:
        done, pending = wait(pending, timeout=0.25, return_when=FIRST_COMPLETED)
        _drain(queue, bar)
        for f in done:
            try:
                name, res, err = f.result()
            except Exception as exc:  # a worker that crashed or raised something unexpected
                name, res = names_of[f], ""
                err = f"scenario '{name}' failed in its worker process: {type(exc).__name__}: {exc}"
            if err:
                for p in pending:
                    p.cancel()
                raise DemoError(err)
            out[name] = res
    _drain(queue, bar)
    return out


class _BarFeed:
    """The progress queue of the one-process case: updates the bar directly."""

    def __init__(self, bar: Any) -> None:
        self.bar = bar

    def put(self, dt: float) -> None:
        self.bar.update(max(0.0, min(dt, self.bar.total - self.bar.n)))


def _drain(queue: Any, bar: Any) -> None:
    feed = _BarFeed(bar)
    while True:
        try:
            feed.put(queue.get_nowait())
        except Empty:
            return


def run_demo(plan: DemoPlan, progress: bool = True) -> dict[str, ScenarioResult]:
    from tqdm import tqdm

    out = plan.out
    for stale in ("report.md", "metrics.json", "FAILED.txt"):
        (out / stale).unlink(missing_ok=True)
    (out / "configs").mkdir(exist_ok=True)
    for name, cfg in plan.configs.items():
        config_mod.dump(cfg, out / "configs" / f"{name}.yaml")
    total = sum(SIM_SECONDS[n] for n in plan.scenarios) * plan.time_scale
    if plan.printed_damping_check:
        total += 15.0 * plan.time_scale
    bar = tqdm(
        total=round(total, 1),
        unit="sim s",
        desc="lapwrench demo",
        disable=not progress,
        mininterval=1.0,
        bar_format="{desc}: {percentage:3.0f}%|{bar}| {n:.0f}/{total:.0f} sim s [{elapsed}<{remaining}{postfix}]",
    )
    t0 = time.perf_counter()
    names = list(plan.scenarios) + ([PRINTED_DAMPING] if plan.printed_damping_check else [])
    try:
        done = _run_tasks(plan, names, bar)
    except (DemoError, KeyboardInterrupt) as exc:
        bar.close()
        _write_failed(out, exc)
        raise
    bar.update(max(0.0, bar.total - bar.n))
    bar.close()
    results = {n: done[n] for n in plan.scenarios}
    figures = {n: _plots(n, r, out, plan.configs[n]) for n, r in results.items()}  # type: ignore[arg-type]
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
        "sim_s": sum(sum(float(r.metrics["duration_s"]) for r in res.runs) for res in results.values()),  # type: ignore[union-attr]
        "instrument_source": _instrument_sources(results),  # type: ignore[arg-type]
        "printed_damping_check": check,
        "notes": report.demo_notes(plan.time_scale, plan.robot, plan.skipped),
    }
    report.write_metrics(out, results, meta)  # type: ignore[arg-type]
    report.write_report(out, results, meta, figures)  # type: ignore[arg-type]
    return results  # type: ignore[return-value]


def _write_failed(out: Path, exc: BaseException) -> None:
    """``FAILED.txt``: why the run stopped (and where, for an unexpected exception), in place of the
    report the run deleted at its start."""
    text = "interrupted (Ctrl-C); no report was written" if isinstance(exc, KeyboardInterrupt) else str(exc)
    cause = exc.__cause__
    if cause is not None:
        text += "\n\n" + "".join(traceback.format_exception(cause))
    with contextlib.suppress(OSError):
        (out / "FAILED.txt").write_text(text + "\n")


def _plots(name: str, res: ScenarioResult, out: Path, cfg: config_mod.Config) -> list[str]:
    stem = name.replace("-", "_")
    cues = report.plot_cues(res, out, stem)  # every cue the config ran, by name
    own = {"grip": report.plot_grip, "rcm-disturbance": report.plot_disturbance, "hard-push": report.plot_hard_push}
    if name in own:
        return own[name](res, out) + cues
    if name in cue_scenarios.SCENARIOS:
        return cue_scenarios.plot(name, res, out) + cues
    figs = report.plot_tracking_run(res, out, stem) + cues
    if res.frames:
        figs.append(report.snapshot_strip(res.frames, cfg, out / f"{stem}_snapshots.png"))
    if (out / f"{name}.mp4").exists():
        figs.append(f"{name}.mp4")
    return figs


def _printed_damping_check(opts: ScenarioOptions, robot: str) -> str:
    """Needle search on ``robot`` with the damping table exactly as printed (one k_t for every cue,
    k_f = 2), to show why the defaults depart from it."""
    cfg = config_mod.load().replace(robot={"kind": robot}, viscous={"k_f": 2.0, "k_t_unguided": 150.0})
    try:
        res = needle_search(cfg, opts)
    except SimulationUnstableError as exc:
        return (
            f"Needle search with the printed k_t = 150 N m s and k_f = 2 N s/m: the run stopped at "
            f"t = {exc.time:.2f} s ({exc.quantity} = {exc.value}): the nearly undamped insertion axis let the "
            "scope slide out of the trocar while the hand swept the view. The defaults therefore use k_f = 150 N s/m "
            "and give the tracking cue its own k_t_unguided = 2 N m s (the printed k_t = 150 stays for the hand)."
        )
    m = res.metrics
    median = m.get("tracking_error_median_px")
    tracking = "no instrument tracked" if median is None else f"tracking error median {median:.0f} px"
    return (
        "Needle search with the printed damping completed (the envelope's depth walls now keep the scope in): "
        f"RCM max {m['rcm_error_max_mm']:.2f} mm, {tracking}, insertion drift {m['insertion_drift_mm']:.1f} mm."
    )


def _instrument_sources(results: dict[str, ScenarioResult]) -> str:
    sources = [f"{name}: {r.instrument_source}" for name, r in results.items() if r.instrument_source]
    return "; ".join(sources) or "none (no tracking scenario run)"
