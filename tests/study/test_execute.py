"""One job turned into table rows (lapwrench.study.execute): metric cells, the one-line error, rows of a
good and a failed job, and run_job on a real (tiny) simulation and on jobs that cannot run."""

from __future__ import annotations

import dataclasses
import math
from fractions import Fraction
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
import yaml

from lapwrench.study.execute import MAX_ERROR_CHARS, job_rows, metric_cells, one_line, run_job, scalar
from lapwrench.study.spec import Job, expand, from_dict


def _job(**over: Any) -> Job:
    data = {"name": "t", "scenarios": ["rcm-disturbance"], "seeds": [0], "time_scale": 0.05}
    data.update(over)
    return expand(from_dict(data))[0]


# --------------------------------------------------------------------------- scalar / metric_cells


@pytest.mark.parametrize(("value", "expected"), [
    (True, 1.0), (False, 0.0), (np.bool_(True), 1.0), (np.bool_(False), 0.0),
    (3, 3.0), (np.int64(-4), -4.0), (np.float64(2.5), 2.5), (np.float32(0.5), 0.5), (Fraction(1, 4), 0.25),
    ("high", "high"), ("", ""),
])
def test_scalar_converts_numbers_bools_and_text(value: object, expected: object) -> None:
    out = scalar(value)
    assert out == expected and type(out) is type(expected)


@pytest.mark.parametrize("value", [None, math.inf, -math.inf, math.nan, np.float64("inf"), np.float64("nan")])
def test_scalar_missing_and_non_finite_become_nan(value: object) -> None:
    out = scalar(value)
    assert isinstance(out, float) and math.isnan(out)


@pytest.mark.parametrize("value", [[1.0, 2.0], (1,), {"a": 1}, np.array([1.0, 2.0]), b"x", 1 + 2j, object()])
def test_scalar_of_anything_else_is_no_cell(value: object) -> None:
    assert scalar(value) is None


def test_metric_cells_prefix_convert_and_drop_non_scalars() -> None:
    cells = metric_cells({"rcm_error_max_mm": np.float64(0.7), "target_met": np.bool_(True), "t": None,
                          "curve": [1.0, 2.0], "label": "high", "big": math.inf}, "m.")
    assert set(cells) == {"m.rcm_error_max_mm", "m.target_met", "m.t", "m.label", "m.big"}
    assert cells["m.rcm_error_max_mm"] == 0.7 and cells["m.target_met"] == 1.0 and cells["m.label"] == "high"
    assert math.isnan(cells["m.t"]) and math.isnan(cells["m.big"])
    assert metric_cells({}, "s.") == {}


# --------------------------------------------------------------------------- one_line


def test_one_line_names_the_type_and_joins_lines() -> None:
    text = one_line(ValueError("first line\n  second\tline\r\nthird"))
    assert text == "ValueError: first line second line third"


def test_one_line_cuts_a_long_message() -> None:
    text = one_line(RuntimeError("x" * 10_000 + "\n" + "y" * 100))
    assert len(text) == MAX_ERROR_CHARS and text.endswith("...") and text.startswith("RuntimeError: xxx")
    assert "\n" not in text


def test_one_line_of_an_empty_message() -> None:
    assert one_line(KeyError()) == "KeyError:"


# --------------------------------------------------------------------------- job_rows


def _fake_result() -> SimpleNamespace:
    runs = [SimpleNamespace(label="with adaptation", metrics={"rcm_error_max_mm": 0.5, "ok": True, "trace": [1]}),
            SimpleNamespace(label="without adaptation", metrics={"rcm_error_max_mm": 2.0, "ok": False})]
    return SimpleNamespace(runs=runs, metrics={"target_met": np.bool_(True), "note": None})


def test_job_rows_one_ok_row_per_run() -> None:
    job = _job(grid={"viscous.k_t": [120.0], "world.surgeon_force": [1.2]})
    rows = job_rows(job, "mystudy", _fake_result(), None, 1.25)  # type: ignore[arg-type]
    assert [r["label"] for r in rows] == ["with adaptation", "without adaptation"]
    for r in rows:
        assert r["run_id"] == job.run_id and r["study"] == "mystudy" and r["scenario"] == "rcm-disturbance"
        assert r["seed"] == 0 and r["status"] == "ok" and r["error"] is None and r["wall_s"] == 1.25
        assert r["p.viscous.k_t"] == 120.0 and r["p.world.surgeon_force"] == 1.2
        assert r["s.target_met"] == 1.0 and math.isnan(r["s.note"])
        assert "m.trace" not in r
        assert yaml.safe_load(r["config"]) == job.config  # the resolved config, loadable back
    assert (rows[0]["m.rcm_error_max_mm"], rows[0]["m.ok"]) == (0.5, 1.0)
    assert (rows[1]["m.rcm_error_max_mm"], rows[1]["m.ok"]) == (2.0, 0.0)


def test_job_rows_failed_is_one_row_with_the_error() -> None:
    job = _job(grid={"robot": ["fr3"]})
    (row,) = job_rows(job, "s", None, "RuntimeError: boom", 0.5)
    assert row["status"] == "failed" and row["error"] == "RuntimeError: boom" and row["label"] is None
    assert row["p.robot"] == "fr3" and row["run_id"] == job.run_id
    assert not any(k.startswith(("m.", "s.")) for k in row)
    assert yaml.safe_load(row["config"])["robot"]["kind"] == "fr3"


# --------------------------------------------------------------------------- run_job


@pytest.fixture(scope="module")
def tiny_rows() -> tuple[Job, list[dict]]:
    """grip at time scale 0.05 (a 0.5° view change at three grip levels), default world, seed 0: a real
    simulation, the shortest a study runs."""
    job = _job(scenarios=["grip"])
    return job, run_job(job, "tiny")


def test_run_job_of_a_real_tiny_job(tiny_rows: tuple[Job, list[dict]]) -> None:
    job, rows = tiny_rows
    assert len(rows) == 3
    assert {r["label"] for r in rows} == {"high", "medium", "low"}
    for r in rows:
        assert r["status"] == "ok" and r["error"] is None and r["run_id"] == job.run_id
        assert math.isfinite(r["m.rcm_error_max_mm"]) and r["m.rcm_error_max_mm"] >= 0.0
        assert r["wall_s"] > 0.0
        assert all(isinstance(v, float | str) for k, v in r.items() if k.startswith(("m.", "s.")))
    summary = rows[0]["s.completion_falls_as_delta_rises"]
    assert summary in (0.0, 1.0)
    assert all(r["s.completion_falls_as_delta_rises"] == summary for r in rows)  # repeated on every run's row
    assert not any(k == "s.completion_time_s" for r in rows for k in r)  # a list in the summary: no cell


def test_run_job_never_raises_on_an_invalid_config() -> None:
    job = _job()
    bad = dataclasses.replace(job, config={**job.config, "viscous": {**job.config["viscous"], "k_t": -1}})
    rows = run_job(bad, "t")
    assert len(rows) == 1
    (row,) = rows
    assert row["status"] == "failed" and row["label"] is None
    assert "viscous.k_t" in row["error"] and "\n" not in row["error"]
    assert row["error"].startswith("ConfigError: ")
    assert yaml.safe_load(row["config"])["viscous"]["k_t"] == -1  # the config that failed is kept


@pytest.mark.parametrize(("change", "named"), [
    ({"scenario": "no-such-scenario"}, "KeyError"),
    ({"world": {"surgeon_force": -1.0}}, "world.surgeon_force"),
    ({"world": {"nosuch": 1.0}}, "nosuch"),
    ({"world": "not a mapping"}, "world"),
    ({"config": {"nosuch": {}}}, "nosuch"),
    ({"config": "not a mapping"}, "Error"),
])
def test_run_job_turns_any_failure_into_one_failed_row(change: dict, named: str) -> None:
    rows = run_job(dataclasses.replace(_job(), **change), "t")
    assert len(rows) == 1 and rows[0]["status"] == "failed"
    assert named in rows[0]["error"]


def test_a_worker_running_jobs_imports_neither_pandas_nor_matplotlib() -> None:
    """Every Ray worker imports what runs a job (execute, and spec for Job); the report's pandas and
    matplotlib (0.7 of its 1.5 s of imports) belong to the process that writes the report only."""
    import subprocess
    import sys

    code = "import sys, lapwrench.study.execute; print(sorted({'pandas', 'matplotlib'} & set(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert out.stdout.strip() == "[]"
