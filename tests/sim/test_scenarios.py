"""The paper's experiments in the simulated world (durations shortened, physics unchanged)."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.sim.scenarios import ScenarioOptions, grip, needle_search, rcm_disturbance, workflow

pytestmark = pytest.mark.slow  # full scenarios in the MuJoCo world

PAPER = load()
TRACKING = load()  # the shipped defaults serve the tracking scenarios too


def _physical(m: dict) -> None:
    assert m["references_inside_limits"], m
    assert m["rcm_error_max_mm"] <= 2.0, m


def test_grip_completion_time_falls_as_delta_rises() -> None:
    res = grip(PAPER, ScenarioOptions(time_scale=0.5))
    times = res.metrics["completion_time_s"]
    assert all(t is not None for t in times), times
    assert times[0] < times[1] < times[2]
    deltas = res.metrics["delta_mean"]
    assert deltas[0] == pytest.approx(2.0, abs=0.15)
    assert deltas[1] == pytest.approx(1.1, abs=0.15)
    assert deltas[2] == pytest.approx(0.3, abs=0.1)
    for run in res.runs:
        _physical(run.metrics)


@pytest.mark.parametrize("time_scale", [0.05, 0.1])
def test_a_short_grip_run_still_turns_the_view(time_scale: float) -> None:
    """At --time-scale 0.1 the 1° adjustment was within the hand's tolerance from the start: every run was
    empty and the report showed zeros."""
    res = grip(PAPER, ScenarioOptions(time_scale=time_scale))
    for run in res.runs:
        assert len(run.trace["t"]) > 100 and run.metrics["delta_mean"] > 0.0, run.label
    assert res.metrics["completion_time_s"][0] is not None


def test_rcm_disturbance_adaptation_relieves_the_trocar() -> None:
    res = rcm_disturbance(PAPER, ScenarioOptions(time_scale=0.5))
    with_, without = (r.metrics for r in res.runs)
    assert with_["force_peak_after_load_N"] > 5.0  # the load really pushed
    assert with_["force_back_below_5N_after_s"] is not None and with_["force_back_below_5N_after_s"] <= 3.0
    assert with_["force_final_N"] < 5.0
    assert with_["rcm_shift_mm"] > 3.0
    assert without["force_final_N"] > 7.0
    assert without["rcm_shift_mm"] == pytest.approx(0.0, abs=1e-6)
    assert res.metrics["target_met"]


def test_needle_search_modes_follow_the_paper_sequence() -> None:
    # full durations: with the paper's k_t = 150 for the hand the search takes ~12 s (Fig. 4 speeds)
    res = needle_search(TRACKING, ScenarioOptions(time_scale=1.0, detector="projected"))
    m = res.metrics
    modes = [mode for _, mode in m["mode_timeline"]]
    first_handle = next(i for i, x in enumerate(modes) if "handle" in x)
    assert "tracking" in modes[:first_handle]  # tracking only first
    assert "handle-dominant" in modes or "handle+tracking" in modes
    last_handle = max(i for i, x in enumerate(modes) if "handle" in x)
    assert "tracking" in modes[last_handle:]  # tracking re-engages after the release
    assert "projected" in res.instrument_source
    _physical(m)


def test_workflow_alternates_handle_and_tracking() -> None:
    # full durations: the hand moves at the speeds of Fig. 4 (paper k_t), which a shortened script outruns
    res = workflow(TRACKING, ScenarioOptions(time_scale=1.0, detector="projected"))
    modes = {mode for _, mode in res.metrics["mode_timeline"]}
    assert {"tracking", "handle"} <= modes or {"tracking", "handle-dominant"} <= modes
    _physical(res.metrics)
    assert res.metrics["tracking_error_median_px"] < 200.0


def test_tracking_runs_on_the_shipped_detector() -> None:
    res = needle_search(TRACKING, ScenarioOptions(time_scale=0.3))
    assert "YOLO ONNX" in res.instrument_source
    assert "latency 40 ms" in res.instrument_source and "inference median" in res.instrument_source
    modes = {mode for _, mode in res.metrics["mode_timeline"]}
    assert "tracking" in modes  # detections on rendered frames engaged the tracking wrench
    _physical(res.metrics)


def test_the_physical_rcm_error_is_measured_from_the_unloaded_incision() -> None:
    res = rcm_disturbance(PAPER, ScenarioOptions(time_scale=0.5))
    tr = res.runs[1].trace  # without adaptation: the housing moved 10 mm, the robot held its pivot
    assert tr["rcm_error_phys"][-1] * 1e3 == pytest.approx(9.0, abs=1.5)
    F = np.linalg.norm(tr["contact_force"][-1])
    assert pytest.approx(1000.0 * tr["rcm_error_phys"][-1], rel=0.1) == F  # wall stiffness 1 N/mm
