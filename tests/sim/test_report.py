"""The demo's report (:mod:`lapwrench.sim.report`), built from small synthetic results: the Markdown page
and metrics.json (the plots it links: tests/sim/test_plots.py). The demo end to end (which calls these
with real runs) is in tests/sim/test_demo.py."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from sim.report_data import META, disturbance, grip, hard_push, needle_search

from lapwrench.sim import report
from lapwrench.sim.results import ScenarioResult


def write(tmp_path: Path, results: dict[str, ScenarioResult], figures: dict | None = None, **meta: object) -> str:
    path = report.write_report(tmp_path, results, {**META, **meta}, figures or {})
    assert path == tmp_path / "report.md"
    return path.read_text()


# -- report.md -------------------------------------------------------------------------------------
def test_a_report_without_scenarios_has_its_header_and_notes(tmp_path: Path) -> None:
    text = write(tmp_path, {}, notes=["first note", "second note"])
    assert text.startswith("# lapwrench — simulated phantom experiments\n")
    assert "Seed 7, robot fr3, physics timestep 0.5 ms" in text
    assert "Total wall time 12 s for 30 s of simulated time" in text
    assert "Instrument image points: **classical**." in text
    assert "- first note\n- second note" in text
    assert "## " in text and "## Grip" not in text and "## Incision" not in text


@pytest.mark.parametrize("missing", ["seed", "robot", "wall_s", "instrument_source"])
def test_a_missing_meta_field_is_named(tmp_path: Path, missing: str) -> None:
    meta = {k: v for k, v in META.items() if k != missing}
    with pytest.raises(KeyError, match=missing):
        report.write_report(tmp_path, {}, meta, {})


def test_the_grip_table_sets_each_run_beside_the_paper(tmp_path: Path) -> None:
    text = write(tmp_path, {"grip": grip()}, {"grip": ["grip.png"]})
    assert "| high | 2.00 (2.01) | 6.00 (6.32) | 0.50 |" in text
    assert "| medium | 1.10 (1.13) | — (11.0) | 0.50 |" in text  # a run that never completed
    assert "Completion time falls as δ rises: **False**." in text
    assert "![grip](grip.png)" in text


def test_the_disturbance_table_rounds_and_marks_missing_values(tmp_path: Path) -> None:
    text = write(tmp_path, {"rcm-disturbance": disturbance()}, {"rcm-disturbance": ["a.png", "b.png"]})
    assert "| adaptive | 7.25 | — | 3.00 | 9.88 |" in text
    assert "Met: **True**." in text
    assert "![disturbance](a.png)\n![disturbance](b.png)" in text


def test_a_tracking_section_compresses_the_modes_and_marks_what_was_not_measured(tmp_path: Path) -> None:
    text = write(tmp_path, {"needle-search": needle_search()}, {"needle-search": ["n.png", "needle-search.mp4"]})
    assert "## Needle search (paper Fig. 6-7)" in text and "## Workflow" not in text
    assert "Mode sequence: idle → tracking → handle\n" in text
    assert "RCM error max 1.50 mm (RMS 0.40)" in text
    assert "tracking error median — px" in text  # no instrument seen: no figure, not a made-up one
    assert "n/a cycles over the 800 µs budget" in text
    assert "![needle-search](needle-search.mp4)" in text


def test_the_hard_push_table_marks_each_run_against_the_targets(tmp_path: Path) -> None:
    text = write(tmp_path, {"hard-push": hard_push()})
    assert "## Hard pushes (issue 9)" in text
    assert "pushes for 2.00 s" in text and "physical RCM error ≤ 3 mm, trocar force ≤ 40 N" in text
    rows = [line for line in text.splitlines() if line.startswith(("| lateral", "| axial"))]
    assert len(rows) == 3
    assert rows[0].endswith("| 3: depth_max×3 | — | True | pass |")
    assert rows[1].endswith("| hold at 0.500 s: rcm | True | **FAIL** (RCM) |")
    assert "**1 of 3 runs meet every target**; 1 ended early" in text
    assert "Tip depth at the start 60.0 mm" in text
    assert "Still moving along the shaft (> 1 mm/s) at the end of the run: lateral 30 N." in text


def test_the_printed_damping_check_gets_its_section(tmp_path: Path) -> None:
    assert "## The printed damping" not in write(tmp_path, {})
    text = write(tmp_path, {}, printed_damping_check="the run stopped at t = 2.00 s")
    assert "## The printed damping" in text and "the run stopped at t = 2.00 s" in text


# -- metrics.json ------------------------------------------------------------------------------------
def test_metrics_json_holds_every_scenario_and_run_with_numpy_values_as_json(tmp_path: Path) -> None:
    res = disturbance()
    res.runs[0].metrics["peak_tick"] = np.int64(42)
    res.metrics["shift"] = np.array([1.0, 2.5])
    path = report.write_metrics(tmp_path, {"rcm-disturbance": res}, {**META, "ratio": np.float32(0.5)})
    data = json.loads(path.read_text())
    assert data["meta"]["seed"] == 7 and data["meta"]["ratio"] == 0.5
    scen = data["scenarios"]["rcm-disturbance"]
    assert scen["metrics"] == {"target_met": True, "shift": [1.0, 2.5]}
    assert scen["runs"]["adaptive"]["peak_tick"] == 42
    assert scen["runs"]["adaptive"]["force_back_below_5N_after_s"] is None


def test_a_value_json_cannot_hold_is_named(tmp_path: Path) -> None:
    res = disturbance()
    res.metrics["bad"] = {1, 2}
    with pytest.raises(TypeError, match="not JSON serialisable: set"):
        report.write_metrics(tmp_path, {"rcm-disturbance": res}, META)


@pytest.mark.parametrize("bad", [math.nan, math.inf, np.float64("nan")])
def test_a_non_finite_metric_is_written_as_null(tmp_path: Path, bad: float) -> None:
    res = disturbance()
    res.runs[0].metrics["force_final_N"] = bad

    def refuse(name: str) -> None:
        raise ValueError(f"not JSON: {name}")

    path = report.write_metrics(tmp_path, {"rcm-disturbance": res}, META)
    data = json.loads(path.read_text(), parse_constant=refuse)
    assert data["scenarios"]["rcm-disturbance"]["runs"]["adaptive"]["force_final_N"] is None


# -- plots -------------------------------------------------------------------------------------------
def test_the_notes_say_how_the_demo_ran() -> None:
    notes = report.demo_notes(0.25, "fr3")
    assert "Simulation time scale 0.25 (1 = the paper's durations)." in notes
    assert any(n.startswith("Machine: ") for n in notes)
    assert not any("left out" in n for n in notes)
    skipped = report.demo_notes(1.0, "ur5e", ("grip", "hard-push"))
    assert skipped[-1] == "Robot ur5e (simulation only): grip, hard-push left out, tuned for the Franka arms."
