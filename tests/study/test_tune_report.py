"""The tuning report (lapwrench.study.tune_report) from synthetic trial rows: counts, the best-config line,
the table, the errors, and the trade-off plot."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib import image as mpimg

from lapwrench.study.tune_report import SHOWN_TRIALS, plot_tradeoff, write_tune_report
from lapwrench.study.tune_spec import TuneSpec, from_dict

SPEC: TuneSpec = from_dict({
    "name": "fast-and-safe", "scenarios": ["grip", "hard-push"], "seeds": [0, 1], "time_scale": 0.5,
    "search": {"viscous.k_t": {"loguniform": [60, 300]}, "tracking.ramp": {"choice": ["printed", "c1"]}},
    "objective": {"metric": "completion_time_s", "reduce": "median"},
    "constraints": [{"metric": "rcm_error_max_mm", "max": 1.0}, {"metric": "trocar_force_max_N", "max": 5.0}],
})


def _trial(k_t: float, objective: float, excess: float, feasible: Any, rcm: float = 0.5, force: float = 3.0,
           error: str | None = None) -> dict[str, Any]:
    return {"p.viscous.k_t": k_t, "p.tracking.ramp": "c1", "score": objective, "objective": objective,
            "excess": excess, "failed": 0, "feasible": feasible, "worst.m.rcm_error_max_mm": rcm,
            "worst.m.trocar_force_max_N": force, "error": error}


TRIALS = [
    _trial(120.0, 6.5, 0.0, True),
    _trial(80.0, 5.9, 0.0, True, rcm=0.99),
    _trial(250.0, 4.0, 0.8, False, rcm=1.8),
    _trial(300.0, math.nan, math.nan, False, rcm=math.nan, force=math.nan,
           error="RayTaskError(RuntimeError): the arm\nstopped\n  at t = 3 s"),
    _trial(60.0, 7.2, 0.1, False, force=5.5),
]


def _table_rows(text: str) -> list[list[str]]:
    lines = [ln for ln in text.splitlines() if ln.startswith("| ") and not ln.startswith("| #")]
    return [[c.strip() for c in ln.strip("|").split("|")] for ln in lines]


def test_report_with_feasible_and_infeasible_trials(tmp_path: Path) -> None:
    best = tmp_path / "best.yaml"
    path = write_tune_report(TRIALS, SPEC, tmp_path, best_config=best, check="passed (2 scenarios)")
    assert path == tmp_path / "tune_report.md"
    text = path.read_text()
    assert text.startswith("# Tuning 'fast-and-safe'")
    assert "grip, hard-push" in text and "seeds 0, 1" in text and "time scale 0.5" in text
    assert "5 trials" in text
    assert "median of `completion_time_s`" in text
    assert "`rcm_error_max_mm` ≤ 1" in text and "`trocar_force_max_N` ≤ 5" in text
    assert "**2 of 5 trials met every constraint.**" in text
    assert f"`best.yaml` (load it with `--config {best}`)" in text
    assert "passed (2 scenarios)" in text
    assert "no configuration was written" not in text
    assert "![trade-off](tune_tradeoff.png)" in text
    img = mpimg.imread(tmp_path / "tune_tradeoff.png")
    assert img.shape[0] > 100 and img.shape[1] > 100 and float(np.std(img)) > 0.01


def test_report_table_has_one_row_per_trial_with_formatted_cells(tmp_path: Path) -> None:
    text = write_tune_report(TRIALS, SPEC, tmp_path, best_config=None, check=None).read_text()
    header = next(ln for ln in text.splitlines() if ln.startswith("| #"))
    cells = [c.strip() for c in header.strip("|").split("|")]
    assert cells[:5] == ["#", "viscous.k_t", "tracking.ramp", "feasible", "completion_time_s"]
    rows = _table_rows(text)
    assert len(rows) == len(TRIALS)
    assert all(len(r) == len(cells) for r in rows)
    assert rows[0][:5] == ["1", "120", "c1", "yes", "6.5"]
    assert rows[2][3] == "no"
    assert rows[3][4] == "—" and rows[3][5] == "—"  # NaN objective and worst value
    assert "| 1 |" not in header


def test_worst_columns_are_headed_with_the_full_metric_name(tmp_path: Path) -> None:
    text = write_tune_report(TRIALS, SPEC, tmp_path, best_config=None, check=None).read_text()
    header = next(ln for ln in text.splitlines() if ln.startswith("| #"))
    assert "rcm_error_max_mm (worst)" in header and "trocar_force_max_N (worst)" in header


def test_errors_are_listed_on_one_line_each(tmp_path: Path) -> None:
    long_error = "ValueError: " + "z" * 1000
    trials = [*TRIALS, _trial(70.0, math.nan, math.nan, False, error=long_error)]
    text = write_tune_report(trials, SPEC, tmp_path, best_config=None, check=None).read_text()
    section = text.split("## Trials that raised", 1)[1]
    items = [ln for ln in section.splitlines() if ln.startswith("- ")]
    assert items[0] == "- RayTaskError(RuntimeError): the arm stopped at t = 3 s"
    assert len(items) == 2 and len(items[1]) <= 302


def test_no_feasible_trial_says_no_configuration_was_written(tmp_path: Path) -> None:
    trials = [t for t in TRIALS if t["feasible"] is not True]
    text = write_tune_report(trials, SPEC, tmp_path, best_config=None, check=None).read_text()
    assert "**0 of 3 trials met every constraint.**" in text
    assert "No trial met every constraint: no configuration was written." in text
    assert "Best configuration" not in text
    assert (tmp_path / "tune_tradeoff.png").is_file()  # infeasible points are still plotted


def test_no_finite_trial_gives_no_plot(tmp_path: Path) -> None:
    trials = [_trial(100.0, math.nan, math.nan, False, error="RuntimeError: x")]
    text = write_tune_report(trials, SPEC, tmp_path, best_config=None, check=None).read_text()
    assert not (tmp_path / "tune_tradeoff.png").exists()
    assert "tune_tradeoff.png" not in text
    assert "no configuration was written" in text


def test_no_trials_at_all(tmp_path: Path) -> None:
    text = write_tune_report([], SPEC, tmp_path, best_config=None, check=None).read_text()
    assert "**0 of 0 trials met every constraint.**" in text and "## Best 0 trials" in text
    assert _table_rows(text) == []


def test_only_the_first_trials_are_tabled(tmp_path: Path) -> None:
    trials = [_trial(60.0 + i, 5.0 + i, 0.0, True) for i in range(SHOWN_TRIALS + 7)]
    text = write_tune_report(trials, SPEC, tmp_path, best_config=tmp_path / "b.yaml", check=None).read_text()
    assert f"## Best {SHOWN_TRIALS} trials" in text
    assert len(_table_rows(text)) == SHOWN_TRIALS
    assert f"**{SHOWN_TRIALS + 7} of {SHOWN_TRIALS + 7} trials" in text


def test_report_without_constraints(tmp_path: Path) -> None:
    spec = from_dict({"scenarios": ["grip"], "search": {"viscous.k_t": {"uniform": [60, 300]}},
                      "objective": {"metric": "completion_time_s"}})
    text = write_tune_report([{"p.viscous.k_t": 100.0, "objective": 5.0, "excess": 0.0, "feasible": True}], spec,
                             tmp_path, best_config=tmp_path / "best.yaml", check=None).read_text()
    assert "Constraints" not in text and "**1 of 1 trials" in text
    assert _table_rows(text) == [["1", "100", "yes", "5"]]


def test_plot_tradeoff_skips_non_numeric_values(tmp_path: Path) -> None:
    trials = [{"objective": "fast", "excess": 0.0, "feasible": True}, {"objective": True, "excess": 0.0},
              {"objective": None, "excess": None}]
    assert plot_tradeoff(trials, SPEC, tmp_path / "p.png") is False
    assert not (tmp_path / "p.png").exists()


def test_numpy_true_counts_as_feasible(tmp_path: Path) -> None:
    trials = [_trial(120.0, 6.5, 0.0, np.bool_(True))]
    text = write_tune_report(trials, SPEC, tmp_path, best_config=tmp_path / "b.yaml", check=None).read_text()
    assert "**1 of 1 trials met every constraint.**" in text


def test_a_trial_with_a_failed_run_lists_that_failure(tmp_path: Path) -> None:
    failed = {**_trial(90.0, math.nan, 1.0, False), "failed": 1,
              "run_error": "SafetyStopError: safety supervisor stopped the robot at t = 1.234 s: rcm"}
    text = write_tune_report([*TRIALS, failed], SPEC, tmp_path, best_config=None, check=None).read_text()
    section = text.split("## Trials with a failed run", 1)[1]
    assert "- SafetyStopError: safety supervisor stopped the robot at t = 1.234 s: rcm" in section
    assert "## Trials with a failed run" not in write_tune_report(TRIALS, SPEC, tmp_path, best_config=None,
                                                                   check=None).read_text()
