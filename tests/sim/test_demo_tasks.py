"""The demo's tasks: the detector threads per worker, whether frames are drawn beside the loop, the
order the workers take the tasks in, and a stop signal while the workers start."""

from __future__ import annotations

import gc
import multiprocessing.util
import signal
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from tqdm import tqdm

from lapwrench.sim.demo import plan_demo
from lapwrench.sim.demo_tasks import (
    IMAGE_SCENARIOS,
    PRINTED_DAMPING,
    TRACKING_SCENARIOS,
    DemoInterrupted,
    core_to_spare,
    detector_threads,
    run_tasks,
    stop_signals,
    task_cost,
)
from lapwrench.sim.scenarios import SCENARIOS, SIM_SECONDS


@pytest.mark.parametrize(
    ("workers", "cpus", "threads"),
    [(1, 8, None), (2, 2, 1), (4, 2, 1), (2, 8, 4), (3, 8, 2)],
)
def test_each_worker_detects_on_its_share_of_the_cores(workers: int, cpus: int, threads: int | None) -> None:
    assert detector_threads(workers, cpus) == threads


def test_the_scenarios_that_render_and_detect_go_first() -> None:
    order = sorted([*SCENARIOS, PRINTED_DAMPING], key=lambda n: -task_cost(n, "shipped"))
    k = len([n for n in order if n in IMAGE_SCENARIOS])
    assert set(order[:k]) == {n for n in order if n in IMAGE_SCENARIOS}  # though hard-push simulates longest
    assert SIM_SECONDS["hard-push"] > SIM_SECONDS["workflow"] and order.index("workflow") < order.index("hard-push")
    assert task_cost(PRINTED_DAMPING, "shipped") == task_cost("needle-search", "shipped")  # it is a needle search


def test_without_an_image_detector_only_the_rendering_weighs_where_the_report_keeps_frames() -> None:
    for name in IMAGE_SCENARIOS:
        assert task_cost(name, "shipped") > task_cost(name, "projected")
    for name in TRACKING_SCENARIOS:  # drawn for the snapshot strip and the video
        assert task_cost(name, "projected") == 2.0 * SIM_SECONDS[name]
    assert task_cost("zoom", "projected") == SIM_SECONDS["zoom"]  # nothing drawn
    assert task_cost("grip", "shipped") == task_cost("grip", "projected") == SIM_SECONDS["grip"]


@pytest.mark.parametrize(("workers", "cpus", "spare"), [(1, 2, True), (2, 2, False), (1, 1, False), (2, 4, True)])
def test_frames_are_drawn_beside_the_loop_only_with_a_core_to_spare(workers: int, cpus: int, spare: bool) -> None:
    assert core_to_spare(workers, cpus) is spare


def _running(pid: int) -> bool:
    """Whether process ``pid`` still runs (a zombie has ended)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.slow  # spawns two workers (stopped while they import)
def test_a_stop_signal_while_the_workers_start_stops_the_demo_once_they_have_started(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capfd: pytest.CaptureFixture[str],
) -> None:
    """SIGTERM once the first worker is forked, before it has its start data: every worker starts all the
    same, then the demo stops (DemoInterrupted, its workers terminated) and no worker prints a traceback.
    A stop raised there used to close the pipe unwritten: that worker died with ``EOFError: Ran out of
    input``, unknown to the pool."""
    plan = plan_demo(tmp_path, ["grip", "rcm-disturbance"], video=False, detector="projected", workers=2)
    spawn = multiprocessing.util.spawnv_passfds
    workers: list[int] = []

    def spawn_then_stop(path: str, args: list[str], passfds: Any) -> int:
        pid = spawn(path, args, passfds)
        if "--multiprocessing-fork" in args:  # a worker (not the resource tracker)
            workers.append(pid)
            if len(workers) == 1:  # to this thread (os.kill would let another thread of the process take it)
                signal.pthread_kill(threading.get_ident(), signal.SIGTERM)
        return pid

    monkeypatch.setattr(multiprocessing.util, "spawnv_passfds", spawn_then_stop)
    with stop_signals() as signals, pytest.raises(DemoInterrupted):
        run_tasks(plan, list(plan.scenarios), tqdm(total=1.0, disable=True))
    monkeypatch.undo()
    assert signals.signum == signal.SIGTERM
    assert len(workers) == plan.workers  # both started before the stop
    gc.collect()  # a start cut short closes its worker's pipe once collected
    for _ in range(600):  # a worker cut short ends by itself, with its traceback
        if not any(_running(pid) for pid in workers):
            break
        time.sleep(0.1)
    assert not any(_running(pid) for pid in workers)
    assert "Traceback" not in capfd.readouterr().err


def test_a_scenario_task_draws_its_figures_where_it_ran(tmp_path: Path) -> None:
    """The tasks draw their scenario's report figures themselves (in the worker that simulated it, beside
    the other workers' runs, not all in a row once every run is done): run_tasks returns each result
    with its figures already in the folder."""
    plan = plan_demo(tmp_path, ["keep-out", "rcm-disturbance"], time_scale=0.05, video=False, detector="projected",
                     workers=1)
    done = run_tasks(plan, list(plan.scenarios), tqdm(total=1.0, disable=True))
    for name in plan.scenarios:
        res = done[name]
        assert not isinstance(res, str)
        assert res.figures and all((tmp_path / f).is_file() for f in res.figures), (name, res.figures)
    assert "keep_out.png" in done["keep-out"].figures  # type: ignore[union-attr]
