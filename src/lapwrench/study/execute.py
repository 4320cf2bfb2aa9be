"""One job of a study, run where it lands (a Ray worker, or this process), turned into table rows.

No Ray here: :func:`run_job` is plain Python, so a job runs the same in a test, in a tuning trial and
on any node of a cluster. A job that fails (the supervisor stopped the arm, the simulation went
unstable, a bad value slipped through) is one row with its error and its configuration; it never
raises.
"""

from __future__ import annotations

import math
import numbers
import time
from typing import Any

import numpy as np
import yaml

from lapwrench import config as config_mod
from lapwrench.sim.results import ScenarioOptions, ScenarioResult
from lapwrench.sim.scenarios import SCENARIOS
from lapwrench.sim.variation import WorldVariation
from lapwrench.study.spec import Job

MAX_ERROR_CHARS = 500


def scalar(value: Any) -> float | str | None:
    """A metric as a table cell: numbers and bools as float (None and non-finite → NaN), text as
    text; anything else (lists, dicts) as None, meaning no cell."""
    if value is None:
        return math.nan
    if isinstance(value, bool | np.bool_):
        return float(value)
    if isinstance(value, numbers.Real):
        x = float(value)
        return x if math.isfinite(x) else math.nan
    if isinstance(value, str):
        return value
    return None


def metric_cells(metrics: dict[str, Any], prefix: str) -> dict[str, float | str]:
    """Every scalar metric of ``metrics`` as a ``<prefix><name>`` cell (see :func:`scalar`)."""
    cells = {f"{prefix}{k}": scalar(v) for k, v in metrics.items()}
    return {k: v for k, v in cells.items() if v is not None}


def one_line(exc: BaseException) -> str:
    """``<ExceptionType>: message`` on one line, cut to :data:`MAX_ERROR_CHARS`."""
    text = " ".join(f"{type(exc).__name__}: {exc}".split())
    return text if len(text) <= MAX_ERROR_CHARS else text[: MAX_ERROR_CHARS - 3] + "..."


def job_rows(job: Job, study: str, result: ScenarioResult | None, error: str | None, wall: float,
             started: float | None = None) -> list[dict]:
    """The rows of one job: one per run of its scenario, or one failed row. ``started``: when the job
    began (Unix time, s), ``wall``: how long it took (s)."""
    base: dict[str, Any] = {
        "run_id": job.run_id, "study": study, "scenario": job.scenario, "seed": job.seed,
        **{f"p.{k}": v for k, v in job.params.items()},
        "wall_s": wall, "started_unix_s": math.nan if started is None else started,
        "config": yaml.safe_dump(job.config, sort_keys=False),
    }
    if result is None:
        return [{**base, "label": None, "status": "failed", "error": error}]
    summary = metric_cells(result.metrics, "s.")
    return [{**base, "label": run.label, "status": "ok", "error": None, **metric_cells(run.metrics, "m."), **summary}
            for run in result.runs]


def run_job(job: Job, study: str) -> list[dict]:
    """Run ``job`` and return its rows (:func:`job_rows`); any exception becomes a failed row."""
    started, t0 = time.time(), time.perf_counter()
    try:
        cfg = config_mod.from_dict(job.config)
        opts = ScenarioOptions(seed=job.seed, time_scale=job.time_scale, detector=job.detector, frames=False,
                               world=WorldVariation.from_dict(job.world))  # a study keeps metrics, no pictures
        result = SCENARIOS[job.scenario](cfg, opts)
    except Exception as exc:
        return job_rows(job, study, None, one_line(exc), time.perf_counter() - t0, started)
    return job_rows(job, study, result, None, time.perf_counter() - t0, started)
