"""The demo's report (:mod:`lapwrench.sim.report`), built from small synthetic results: the Markdown page,
metrics.json, and the plots. The demo end to end (which calls these with real runs) is in
tests/sim/test_demo.py."""

from __future__ import annotations

import json
import math
from pathlib import Path

import matplotlib.image as mpimg
import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.sim import report
from lapwrench.sim.loop import Trace
from lapwrench.sim.results import Run, ScenarioResult

N = 50  # ticks of a synthetic trace
META = {
    "seed": 7, "robot": "fr3", "physics_dt_ms": 0.5, "wall_s": 12.4, "sim_s": 30.0, "instrument_source": "classical"
}


def trace(n: int = N, **extra: np.ndarray) -> Trace:
    """A trace with the columns the plots read: a scope pivoting slowly about a fixed incision."""
    t = np.arange(n) * 1e-3
    s = np.linspace(0.0, 1.0, n)
    d_z = np.stack([np.zeros(n), np.sin(0.1 * s), np.cos(0.1 * s)], axis=1)
    cols = {
        "t": t,
        "delta": 1.0 + s,
        "view_error_deg": 10.0 * (1.0 - s),
        "contact_force": np.stack([np.zeros(n), 4.0 * s, np.ones(n)], axis=1),
        "p_R": np.tile([0.4, 0.0, 0.3], (n, 1)) + 1e-3 * s[:, None],
        "incision": np.tile([0.4, 0.0, 0.3], (n, 1)),
        "p_E": np.tile([0.4, 0.0, 0.1], (n, 1)),
        "d_z": d_z,
        "W_h": np.tile([0.0, 0.0, 0.0, 1.0, 2.0, 2.0], (n, 1)),
        "W_c": np.tile([0.0, 0.0, 0.0, 0.0, 4.0, 3.0], (n, 1)),
        "rcm_error_phys": 1e-3 * s,
        "pixel_error": np.where(s < 0.5, 80.0, np.nan),
        "mode": np.array(["tracking"] * (n // 2) + ["handle"] * (n - n // 2)),
        "tip_depth": 0.06 + 0.01 * s,
        **extra,
    }
    return Trace(columns=cols)  # type: ignore[arg-type]


def grip() -> ScenarioResult:
    runs = [
        Run(label, trace(), {"delta_mean": d, "completion_time_s": c, "rcm_error_max_mm": 0.5})
        for label, d, c in (("high", 2.0, 6.0), ("medium", 1.1, None), ("low", 0.3, 20.0))
    ]
    paper = {"delta": [2.01, 1.13, 0.28], "completion_s": [6.32, 11.0, 19.46]}
    return ScenarioResult("grip", runs, {"paper": paper, "completion_falls_as_delta_rises": False})


def disturbance() -> ScenarioResult:
    m = {"force_peak_after_load_N": 7.25, "force_back_below_5N_after_s": None, "force_final_N": 3.0,
         "rcm_shift_mm": 9.876}
    return ScenarioResult("rcm-disturbance", [Run("adaptive", trace(), m)], {"target_met": True})


def needle_search(**metrics: object) -> ScenarioResult:
    m = {
        "rcm_error_max_mm": 1.5, "rcm_error_rms_mm": 0.4, "trocar_force_max_N": 6.0, "insertion_drift_mm": 3.0,
        "references_inside_limits": True, "real_time_factor": 0.8,
        # 0.1 s flickers between the dwells are left out of the mode sequence
        "mode_timeline": [(0.0, "idle"), (1.0, "tracking"), (1.1, "handle"), (1.2, "tracking"), (3.0, "handle")],
        **metrics,
    }
    return ScenarioResult("needle-search", [Run("run", trace(), {})], m, instrument_source="classical")


def hard_push() -> ScenarioResult:
    def run(label: str, passed: bool, t: bool = True) -> Run:
        m = {
            "kind": label.split()[0], "delta_mean": 1.0, "rcm_error_max_mm": 2.0, "trocar_force_max_N": 30.0,
            "tilt_max_deg": 4.0, "depth_change_min_mm": -2.0, "depth_change_max_mm": 5.0, "tip_depth_min_mm": 58.0,
            "tip_depth_max_mm": 65.0, "tip_depth_start_mm": 60.0, "envelope_hit_ticks": 3,
            "envelope_walls": "depth_max×3" if passed else "", "alarm": None if passed else "hold at 0.500 s: rcm",
            "references_inside_limits": True, "passed": passed, "failed_targets": "" if passed else "RCM",
        }
        return Run(label, trace() if t else Trace(), m)

    targets = {"rcm_error_max_mm": 3.0, "trocar_force_max_N": 40.0, "tip_depth_min_mm": 30.0, "tip_depth_max_mm": 120.0}
    metrics = {"push_s": 2.0, "settle_s": 1.0, "targets": targets, "passed": 1, "runs": 3, "alarms": 1,
               "all_references_inside_limits": True, "still_moving": ["lateral 30 N"]}
    return ScenarioResult("hard-push", [run("lateral 30 N", True), run("axial 50 N", False),
                                        run("axial 80 N", False, t=False)], metrics)


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
def png_size(path: Path) -> tuple[int, int]:
    """(height, width) in pixels of a PNG written by the report."""
    return mpimg.imread(path).shape[:2]


@pytest.mark.parametrize(
    ("plot", "result", "name"),
    [
        (report.plot_grip, grip, "grip.png"),
        (report.plot_disturbance, disturbance, "rcm_disturbance.png"),
        (report.plot_hard_push, hard_push, "hard_push.png"),  # one run stopped before its first tick
    ],
)
def test_each_scenario_plot_writes_its_png(tmp_path: Path, plot, result, name: str) -> None:
    assert plot(result(), tmp_path) == [name]
    h, w = png_size(tmp_path / name)
    assert h > 300 and w > 1000


def test_the_tracking_plot_is_named_after_its_stem(tmp_path: Path) -> None:
    assert report.plot_tracking_run(needle_search(), tmp_path, "needle_search") == ["needle_search.png"]
    assert png_size(tmp_path / "needle_search.png") == (825, 1430)  # 13 x 7.5 in at 110 dpi


def test_cue_columns_split_wrenches_from_telemetry() -> None:
    tr = trace(**{"cue:zoom": np.zeros((N, 6)), "cue:zoom.spread": np.ones(N), "cue:keep-out": np.zeros((N, 6))})
    assert report.cue_columns(tr) == (["cue:zoom", "cue:keep-out"], ["cue:zoom.spread"])
    assert report.cue_columns(trace()) == ([], [])
    assert report.cue_columns(object()) == ([], [])  # not a trace: no columns, no cues


def test_a_result_without_cue_columns_draws_no_cue_plot(tmp_path: Path) -> None:
    assert report.plot_cues(disturbance(), tmp_path, "rcm_disturbance") == []
    assert not list(tmp_path.iterdir())


def test_every_cue_is_plotted_with_no_code_per_cue(tmp_path: Path) -> None:
    wrench = np.tile([0.0, 0.0, 0.0, 3.0, 4.0, 0.0], (N, 1))
    runs = [Run(f"run {k}", trace(**{"cue:mine": wrench, "cue:mine.gain": np.ones(N)}), {}) for k in range(2)]
    assert report.plot_cues(ScenarioResult("custom", runs, {}), tmp_path, "custom") == ["custom_cues.png"]
    h, w = png_size(tmp_path / "custom_cues.png")
    assert (h, w) == (round(2 * 2.6 * 110), 13 * 110)  # one row per run, telemetry beside the wrench


@pytest.mark.parametrize(("count", "panels"), [(1, 1), (4, 4), (20, 6)])
def test_the_snapshot_strip_shows_at_most_six_frames(tmp_path: Path, count: int, panels: int) -> None:
    shots = [(np.full((48, 64, 3), 10 * k, np.uint8), f"t={k}") for k in range(count)]
    assert report.snapshot_strip(shots, load(), tmp_path / "strip.png") == "strip.png"
    assert png_size(tmp_path / "strip.png")[1] == 3 * panels * 110


# -- notes -------------------------------------------------------------------------------------------
def test_the_notes_say_how_the_demo_ran() -> None:
    notes = report.demo_notes(0.25, "fr3")
    assert "Simulation time scale 0.25 (1 = the paper's durations)." in notes
    assert any(n.startswith("Machine: ") for n in notes)
    assert not any("left out" in n for n in notes)
    skipped = report.demo_notes(1.0, "ur5e", ("grip", "hard-push"))
    assert skipped[-1] == "Robot ur5e (simulation only): grip, hard-push left out, tuned for the Franka arms."
