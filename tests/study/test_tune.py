"""lapwrench.study.tune: how a trial is scored (feasible beats infeasible, failures break every
constraint), its jobs, and one real evaluation without Ray (the Ray Tune run itself is exercised
end to end in tests/study/test_cli.py)."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from lapwrench import config as config_mod
from lapwrench.study.tune import PENALTY, Evaluation, config_jobs, evaluate, score_rows
from lapwrench.study.tune_spec import from_dict

SPEC = from_dict({
    "name": "t", "scenarios": ["grip", "rcm-disturbance"], "seeds": [0, 1], "time_scale": 0.05,
    "detector": "projected", "search": {"viscous.k_t": {"uniform": [100, 200]}},
    "objective": {"metric": "duration_s", "reduce": "max"},
    "constraints": [{"metric": "rcm_error_max_mm", "max": 1.0}],
})


def _row(run_id: str, status: str = "ok", **metrics: float) -> dict:
    return {"run_id": run_id, "status": status, **{f"m.{k}": v for k, v in metrics.items()}}


def test_a_feasible_trial_scores_its_objective() -> None:
    ev = score_rows([_row("a", duration_s=2.0, rcm_error_max_mm=0.5), _row("b", duration_s=3.0, rcm_error_max_mm=0.9)],
                    SPEC)
    assert ev.feasible and ev.objective == 3.0 and ev.score == 3.0  # reduce: max
    assert ev.worst == {"m.rcm_error_max_mm": 0.9}


def test_an_infeasible_trial_scores_worse_than_any_feasible_one() -> None:
    bad = score_rows([_row("a", duration_s=0.1, rcm_error_max_mm=1.5)], SPEC)
    assert not bad.feasible
    assert bad.excess == pytest.approx(0.5)
    assert bad.score == pytest.approx(PENALTY * 1.5)
    worse = score_rows([_row("a", duration_s=0.1, rcm_error_max_mm=3.0)], SPEC)
    assert worse.score > bad.score > Evaluation(1e5, 0.0, 0, {}).score


def test_a_failed_run_or_a_missing_metric_breaks_the_constraints() -> None:
    stop = {**_row("b", status="failed"), "error": "SafetyStopError: stopped at t = 1.000 s"}
    failed = score_rows([_row("a", duration_s=1.0, rcm_error_max_mm=0.1), stop], SPEC)
    assert failed.failed == 1 and not failed.feasible and failed.score >= 2 * PENALTY
    assert failed.first_error == "SafetyStopError: stopped at t = 1.000 s"
    missing = score_rows([_row("a", duration_s=1.0)], SPEC)
    assert not missing.feasible and missing.excess == 1.0 and math.isnan(missing.worst["m.rcm_error_max_mm"])
    empty = score_rows([], SPEC)
    assert not empty.feasible and math.isnan(empty.objective)


def test_config_jobs_cover_every_scenario_and_seed_with_the_given_config() -> None:
    cfg = config_mod.load().replace(viscous={"k_t": 123.0})
    jobs = config_jobs(SPEC, cfg, {"viscous.k_t": 123.0})
    assert {(j.scenario, j.seed) for j in jobs} == {(s, k) for s in ("grip", "rcm-disturbance") for k in (0, 1)}
    assert all(j.config["viscous"]["k_t"] == 123.0 and j.time_scale == 0.05 for j in jobs)
    assert len({j.run_id for j in jobs}) == 4


@pytest.mark.slow
def test_evaluate_runs_the_scenarios_and_a_tight_bound_fails() -> None:
    one_seed = from_dict({**_raw(), "seeds": [0], "constraints": [{"metric": "rcm_error_max_mm", "max": 1.0}]})
    ev, rows = evaluate(one_seed, {"viscous.k_t": 150.0})
    assert {(r["scenario"], r["seed"]) for r in rows} == {("grip", 0), ("rcm-disturbance", 0)}
    assert len(rows) == 3 + 2  # grip's three levels, rcm-disturbance with and without adaptation
    assert all(r["status"] == "ok" for r in rows)
    assert all(yaml.safe_load(r["config"])["viscous"]["k_t"] == 150.0 for r in rows)  # the trial's params ran
    assert math.isfinite(ev.objective) and ev.objective >= 6.0  # rcm-disturbance runs at least 6 s
    tight = from_dict({**_raw(), "constraints": [{"metric": "rcm_error_max_mm", "max": 1e-9}]})
    assert not score_rows(rows, tight).feasible


def _raw() -> dict:
    return {"name": "t", "scenarios": ["grip", "rcm-disturbance"], "seeds": [0, 1], "time_scale": 0.05,
            "detector": "projected", "search": {"viscous.k_t": {"uniform": [100, 200]}},
            "objective": {"metric": "duration_s", "reduce": "max"}}


@pytest.mark.slow
def test_a_search_without_a_feasible_trial_removes_an_earlier_best_yaml(tmp_path: Path) -> None:
    """A second search into the same folder that met no constraint left the first search's best.yaml
    beside a report saying "no configuration was written": a stale file passed off as the result."""
    out = tmp_path / "out"
    out.mkdir()
    config_mod.dump(config_mod.load(), out / "best.yaml")  # an earlier search's result
    tune_file = tmp_path / "tune.yaml"
    tune_file.write_text(yaml.safe_dump({**_raw(), "scenarios": ["grip"], "seeds": [0], "trials": 1,
                                         "constraints": [{"metric": "rcm_error_max_mm", "max": -1.0}]}))
    proc = subprocess.run([sys.executable, "-m", "lapwrench.cli", "tune", str(tune_file), "--out", str(out),
                           "--workers", "1", "--quiet"], capture_output=True, text=True, timeout=900,
                          env={**os.environ, "MUJOCO_GL": "egl"})
    assert proc.returncode == 1, proc.stderr[-2000:]
    assert "0 of 1 trials met every constraint" in proc.stdout
    assert not (out / "best.yaml").exists()
    assert "no configuration was written" in (out / "tune_report.md").read_text()
