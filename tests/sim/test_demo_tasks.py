"""The demo's tasks: the detector threads per worker, whether frames are drawn beside the loop, and the
order the workers take the tasks in."""

from __future__ import annotations

import pytest

from lapwrench.sim.demo_tasks import (
    IMAGE_SCENARIOS,
    PRINTED_DAMPING,
    TRACKING_SCENARIOS,
    core_to_spare,
    detector_threads,
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
