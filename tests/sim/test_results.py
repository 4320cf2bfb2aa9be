"""lapwrench.sim.results: the physical metrics every scenario run reports, computed from a run's
trace (here a short grip-and-push run of the closed loop), and the options every scenario takes."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.sim.loop import ClosedLoop, Trace
from lapwrench.sim.results import DEFAULT_OPTIONS, ScenarioOptions, loop_compute_metrics, run_metrics
from lapwrench.sim.variation import WorldVariation
from lapwrench.sim.world import CONTROL_DT


@pytest.fixture(scope="module")
def run() -> tuple[ClosedLoop, Trace]:
    """0.4 s: gripped, pushed sideways with 8 N from 0.1 s."""
    loop = ClosedLoop(load(), seed=0)
    trace = Trace()
    while loop.t < 0.4:
        loop.world.set_hand_wrench(force=np.array([8.0, 0.0, 0.0]) if loop.t >= 0.1 else np.zeros(3))
        loop.record(trace, loop.step(20.0))
    return loop, trace


def test_the_metrics_of_a_run_come_from_its_trace(run: tuple[ClosedLoop, Trace]) -> None:
    loop, trace = run
    m = run_metrics(loop, trace, wall=2.0)
    assert m["duration_s"] == pytest.approx(len(trace["t"]) * CONTROL_DT)
    assert m["real_time_factor"] == pytest.approx(m["duration_s"] / 2.0)
    phys = trace["rcm_error_phys"] * 1e3
    assert m["rcm_error_max_mm"] == pytest.approx(phys.max()) and m["rcm_error_rms_mm"] <= m["rcm_error_max_mm"]
    assert m["rcm_error_max_mm"] < 2.0  # the paper's RCM holds under the push
    assert m["trocar_force_max_N"] == pytest.approx(np.linalg.norm(trace["contact_force"], axis=1).max())
    assert m["references_inside_limits"] is True and 0.0 < m["limit_velocity_usage"] <= 1.0
    assert m["loop_over_budget_cycles"] >= 0 and m["loop_compute_p50_us"] > 0
    assert "tracking_error_median_px" not in m  # no camera: no tracking figures


def test_a_run_without_wall_time_has_no_real_time_factor(run: tuple[ClosedLoop, Trace]) -> None:
    assert run_metrics(*run, wall=0.0)["real_time_factor"] is None


def test_the_loop_figures_need_cycles(run: tuple[ClosedLoop, Trace]) -> None:
    loop, _ = run
    figures = loop_compute_metrics(loop)
    assert figures["loop_compute_p50_us"] <= figures["loop_compute_p99_us"]
    loop.compute_us, kept = [], loop.compute_us
    try:
        assert loop_compute_metrics(loop) == {}
    finally:
        loop.compute_us = kept


def test_the_default_options_are_one_frozen_shared_instance() -> None:
    assert ScenarioOptions() == DEFAULT_OPTIONS and DEFAULT_OPTIONS.detector == "shipped"
    assert DEFAULT_OPTIONS.world == WorldVariation() and DEFAULT_OPTIONS.seed == 0
    with pytest.raises(dataclasses.FrozenInstanceError):
        DEFAULT_OPTIONS.seed = 1  # type: ignore[misc]
