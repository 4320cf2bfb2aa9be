"""The demo's tasks and the worker processes that run them (:func:`run_tasks`): each scenario with its
report figures (:func:`scenario_figures`), and the printed-damping check, in a process of its own (or all
in this one with one worker), the costliest first, with the progress of every worker fed into one bar.
"""

from __future__ import annotations

import contextlib
import gc
import multiprocessing as mp
import os
import signal
import threading
from collections.abc import Iterator
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, replace
from pathlib import Path
from queue import Empty
from typing import Any

from lapwrench import config as config_mod
from lapwrench.sim.loop import SafetyStopError
from lapwrench.sim.results import ScenarioOptions, ScenarioResult
from lapwrench.sim.scenarios import SCENARIOS, SIM_SECONDS, needle_search
from lapwrench.sim.world import SimulationUnstableError
from lapwrench.spawn import STOP_SIGNALS, ensure_resource_tracker, quietly, starting_children

TRACKING_SCENARIOS = ("needle-search", "workflow")


@dataclass(frozen=True)
class DemoPlan:
    """What one ``lapwrench demo`` runs: every input checked (:func:`lapwrench.sim.demo.plan_demo`)."""

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


class DemoError(RuntimeError):
    """A bad demo input, reported before any simulation starts."""


class DemoInterrupted(KeyboardInterrupt):
    """The demo stopped by a signal (Ctrl-C, ``kill``, a closed terminal): no report is written."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum

    @property
    def exit_code(self) -> int:  # 130, 143, 129
        return 128 + self.signum

    @property
    def name(self) -> str:
        return signal.Signals(self.signum).name


class StopSignals:
    """While active (:func:`stop_signals`), the first of :data:`STOP_SIGNALS` raises
    :class:`DemoInterrupted` in the main thread and is kept in ``signum``; any further one is ignored:
    the workers are being stopped and FAILED.txt written."""

    def __init__(self) -> None:
        self.signum: int | None = None

    def __call__(self, signum: int, _frame: object) -> None:
        if self.signum is None:
            self.signum = signum
            raise DemoInterrupted(signum)


@contextlib.contextmanager
def stop_signals() -> Iterator[StopSignals]:
    """SIGINT, SIGTERM and SIGHUP end the demo alike (:class:`StopSignals`); the previous handlers
    are back after the block. Outside the main thread nothing is installed."""
    handler = StopSignals()
    if threading.current_thread() is not threading.main_thread():
        yield handler
        return
    old = {sig: signal.signal(sig, handler) for sig in STOP_SIGNALS}
    try:
        yield handler
    finally:
        for sig, previous in old.items():
            signal.signal(sig, previous if previous is not None else signal.SIG_DFL)


PRINTED_DAMPING = "needle-search, printed damping"


def detector_threads(workers: int, cpus: int | None = None) -> int | None:
    """onnxruntime threads per scenario's detector when ``workers`` processes share ``cpus`` cores
    (default: this machine's): the cores each worker has (at least one), or None (the detector's own
    default) for one worker. The detections do not depend on it; a second thread per worker only
    competes with the other workers' cores (and spins while it waits)."""
    if workers <= 1:
        return None
    return max(1, (cpus or os.cpu_count() or 1) // workers)


def core_to_spare(workers: int, cpus: int | None = None) -> bool:
    """Whether each of ``workers`` processes has a core beside its own on ``cpus`` (default: this
    machine's) for drawing its camera frames in a child process while its loop steps on
    (:class:`~lapwrench.sim.loop.ClosedLoop`'s ``render_in_background``: the same frames, so the same
    results). Not when every core runs a scenario: the child would only take turns with them."""
    return (cpus or os.cpu_count() or 1) >= 2 * workers


IMAGE_SCENARIOS = (*TRACKING_SCENARIOS, "zoom", PRINTED_DAMPING)  # those that render and detect at 25 fps
IMAGE_COST = {"detector": 4.0, "projected": 2.0}
"""Worker seconds per simulated second of an image scenario relative to the others: rendering the frames
costs about what the loop does, the shipped detector's two passes per frame twice that again
(2026-12-02); with the ``projected`` detector only the rendering is left, and only in the tracking
scenarios, whose frames the report keeps (the snapshot strip, the video)."""


def task_cost(name: str, detector: str) -> float:
    """A task's share of the demo's work, to start the costliest first (the greedy order that ends
    the workers closest together): its simulated seconds, weighted by :data:`IMAGE_COST` for the
    scenarios that render and detect."""
    sim_s = SIM_SECONDS.get(name, SIM_SECONDS["needle-search"])  # the printed-damping check is a needle search
    if name not in IMAGE_SCENARIOS:
        return sim_s
    if detector == "projected":
        return sim_s * IMAGE_COST["projected"] if name in TRACKING_SCENARIOS else sim_s
    return sim_s * IMAGE_COST["detector"]


def _init_worker(queue: Any) -> None:
    global _PROGRESS
    _PROGRESS = queue
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the main process's to handle
    parent = mp.parent_process()
    if parent is not None:  # a worker never outlives the demo, however it ended (even SIGKILL)
        threading.Thread(target=_exit_with, args=(parent,), name="lapwrench-demo-orphan", daemon=True).start()


def _exit_with(parent: Any) -> None:
    parent.join()  # returns when the parent process has ended
    os._exit(1)


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
        detector_threads=detector_threads(plan.workers),
        render_in_background=core_to_spare(plan.workers),
    )
    # The runs keep millions of small objects (the per-tick traces) and make no reference cycles:
    # the cyclic garbage collector would only scan them, in pauses of several ms inside the loop.
    gc_was_enabled = gc.isenabled()
    gc.disable()
    try:
        if name == PRINTED_DAMPING:
            return name, _printed_damping_check(opts, plan.robot), None
        res = SCENARIOS[name](plan.configs[name], opts)
    except (SimulationUnstableError, SafetyStopError) as exc:
        return name, "", f"simulation of '{name}' stopped: {exc}. No report was written."
    finally:
        if gc_was_enabled:
            gc.enable()
    # its figures now, in this worker: beside the other workers' simulations, not all in a row at the end
    res.figures = scenario_figures(name, res, plan.out, plan.configs[name])
    return name, res, None


def scenario_figures(name: str, res: ScenarioResult, out: Path, cfg: config_mod.Config) -> list[str]:
    """Draw the report's figures of scenario ``name`` into ``out``; their file names (with the video's,
    if the scenario wrote one)."""
    from lapwrench.sim import cue_scenarios, plots  # matplotlib: imported where the figures are drawn

    stem = name.replace("-", "_")
    cues = plots.plot_cues(res, out, stem)  # every cue the config ran, by name
    own = {"grip": plots.plot_grip, "rcm-disturbance": plots.plot_disturbance, "hard-push": plots.plot_hard_push}
    if name in own:
        return own[name](res, out) + cues
    if name in cue_scenarios.SCENARIOS:
        return cue_scenarios.plot(name, res, out) + cues
    figs = plots.plot_tracking_run(res, out, stem) + cues
    if res.frames:
        figs.append(plots.snapshot_strip(res.frames, cfg, out / f"{stem}_snapshots.png"))
    if (out / f"{name}.mp4").exists():
        figs.append(f"{name}.mp4")
    return figs


def run_tasks(plan: DemoPlan, names: list[str], bar: Any) -> dict[str, ScenarioResult | str]:
    """Run the tasks on ``plan.workers`` processes (costliest first), or in this process with one worker."""
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
    ensure_resource_tracker()  # before the queue's semaphores: a SIGHUP must not end it
    queue = ctx.Queue()
    # the workers start with Ctrl-C ignored (lapwrench.spawn): the main process stops them
    pool = ProcessPoolExecutor(plan.workers, mp_context=ctx, initializer=quietly(_init_worker), initargs=(queue,))
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
    """Submit the tasks costliest first (:func:`task_cost`) and gather their results, feeding the progress bar."""
    order = sorted(names, key=lambda n: -task_cost(n, plan.detector))
    with starting_children():  # the workers start on the first submits: a stop signal waits for their starts
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



def _printed_damping_check(opts: ScenarioOptions, robot: str) -> str:
    """Needle search on ``robot`` with the damping table exactly as printed (one k_t for every cue,
    k_f = 2), to show why the defaults depart from it."""
    cfg = config_mod.load().replace(robot={"kind": robot}, viscous={"k_f": 2.0, "k_t_unguided": 150.0})
    try:
        res = needle_search(cfg, replace(opts, frames=False))  # one sentence in the report: no snapshots
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
