"""``lapwrench tune``: Ray Tune searches the gains of a :class:`~lapwrench.study.tune_spec.TuneSpec`.

Each trial is one configuration: it runs every scenario with every seed (:func:`evaluate`, the same
job runner as a sweep) and reports one score to Ray Tune. The score is the objective when every
constraint holds, and ``PENALTY`` plus the summed relative excesses when one does not, so any
feasible trial beats every infeasible one. The best feasible trial is written as a configuration
that ``--config`` loads (``best.yaml``), checked by loading it back and running the scenarios again.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lapwrench import config as config_mod
from lapwrench.sim.variation import WorldVariation
from lapwrench.study.execute import run_job
from lapwrench.study.space import apply
from lapwrench.study.spec import Job
from lapwrench.study.tune_spec import TuneSpec

PENALTY = 1e6


@dataclass(frozen=True)
class Evaluation:
    """One configuration's result over the scenario set."""

    objective: float  # reduced objective (NaN: no row had it)
    excess: float  # summed relative excess over the constraints (0: all hold)
    failed: int  # jobs that failed
    worst: dict[str, float]  # per constraint metric, the worst value over the rows
    first_error: str | None = None  # the error of the first failed job, if any

    @property
    def feasible(self) -> bool:
        return self.excess == 0.0 and self.failed == 0 and math.isfinite(self.objective)

    @property
    def score(self) -> float:
        if self.feasible:
            return self.objective
        return PENALTY * (1.0 + self.excess + self.failed)


def _reduce(values: list[float], how: str) -> float:
    finite = [v for v in values if math.isfinite(v)]
    if not finite:
        return math.nan
    if how == "max":
        return float(np.max(finite))
    return float(np.median(finite) if how == "median" else np.mean(finite))


def score_rows(rows: list[dict], spec: TuneSpec) -> Evaluation:
    """The :class:`Evaluation` of a trial's rows."""
    ok = [r for r in rows if r["status"] == "ok"]
    failed = len({r["run_id"] for r in rows if r["status"] == "failed"})
    objective = _reduce([float(r.get(spec.objective, math.nan)) for r in ok], spec.reduce)
    excess, worst = 0.0, {}
    for c in spec.constraints:
        values = [float(r.get(c.metric, math.nan)) for r in ok]
        finite = [v for v in values if math.isfinite(v)]
        worst[c.metric] = max(finite) if finite else math.nan
        excess += sum(c.excess(v) for v in values)
    first_error = next((str(r.get("error")) for r in rows if r["status"] == "failed"), None)
    return Evaluation(objective, excess, failed, worst, first_error)


def config_jobs(spec: TuneSpec, cfg: config_mod.Config, params: dict[str, Any]) -> list[Job]:
    """The jobs of one trial: every scenario with every seed, with configuration ``cfg`` (the default world)."""
    s, world = spec.study, WorldVariation().to_dict()
    return [Job(sc, seed, params, config_mod.to_dict(cfg), world, s.time_scale, s.detector)
            for sc in s.scenarios for seed in s.seeds]


def evaluate_config(spec: TuneSpec, cfg: config_mod.Config, params: dict[str, Any] | None = None
                    ) -> tuple[Evaluation, list[dict]]:
    """Run the scenario set with ``cfg`` here (no Ray) and score it."""
    rows = [r for job in config_jobs(spec, cfg, params or {}) for r in run_job(job, spec.name)]
    return score_rows(rows, spec), rows


def evaluate(spec: TuneSpec, params: dict[str, Any]) -> tuple[Evaluation, list[dict]]:
    """One trial: the configuration ``params`` gives, run and scored."""
    cfg, _ = apply(spec.study.base, params)
    return evaluate_config(spec, cfg, params)


def _trainable(spec: TuneSpec) -> Any:
    from ray import tune

    def trial(params: dict[str, Any]) -> None:
        ev, _rows = evaluate(spec, params)
        tune.report({"score": ev.score, "objective": ev.objective, "excess": ev.excess, "failed": ev.failed,
                     "feasible": ev.feasible, "first_error": ev.first_error or "",
                     **{f"worst.{k}": v for k, v in ev.worst.items()}})

    return trial


@dataclass
class TuneOutcome:
    trials: list[dict[str, Any]]  # one per trial: params (p.*), score, objective, excess, feasible, worst.*
    best: dict[str, Any] | None  # the best feasible trial's row
    best_config: Path | None


def run_tune(spec: TuneSpec, out: Path, *, address: str | None = None, workers: int | None = None,
             progress: bool = True) -> TuneOutcome:
    """Search with Ray Tune (random search over ``spec.search``); write ``trials.parquet`` and, when
    a trial met every constraint, ``best.yaml`` (when none did, an earlier search's ``best.yaml`` in
    ``out`` is removed). A KeyboardInterrupt (Ctrl-C) ends the search and propagates, with nothing
    written."""
    import ray
    from ray import tune

    from lapwrench.study.runner import start_ray
    from lapwrench.study.table import to_frame

    # Ray Tune's own SIGINT handler ends the search quietly and returns the trials so far, which would
    # then be written up as the result; ours (lapwrench.cli_signals) raises KeyboardInterrupt instead.
    os.environ["TUNE_DISABLE_SIGINT_HANDLER"] = "1"
    output = os.environ.get("RAY_AIR_NEW_OUTPUT")
    if not progress:  # Tune's new output prints its tables even at verbose 0; its older one prints nothing then
        os.environ["RAY_AIR_NEW_OUTPUT"] = "0"
    try:
        cpus = start_ray(address, workers)
        tuner = tune.Tuner(
            tune.with_resources(_trainable(spec), {"cpu": 1}),
            param_space={k: d.to_tune() for k, d in spec.search.items()},
            tune_config=tune.TuneConfig(metric="score", mode="min", num_samples=spec.trials,
                                        max_concurrent_trials=cpus),
            run_config=tune.RunConfig(name=spec.name, storage_path=str((out / "ray_tune").resolve()),
                                      verbose=1 if progress else 0),
        )
        grid = tuner.fit()
    finally:
        ray.shutdown()
        if output is None:
            os.environ.pop("RAY_AIR_NEW_OUTPUT", None)
        else:
            os.environ["RAY_AIR_NEW_OUTPUT"] = output
    trials = []
    for i in range(len(grid)):  # ray's ResultGrid is a sequence by __getitem__/__len__ (no __iter__ for mypy)
        result = grid[i]
        m = result.metrics or {}
        row = {**{f"p.{k}": v for k, v in (result.config or {}).items()},
               **{k: m.get(k, math.nan) for k in ("score", "objective", "excess", "failed")},
               "feasible": m.get("feasible") in (True, 1),  # Ray may hand a bool back as 1 or numpy.bool_
               **{k: v for k, v in m.items() if k.startswith("worst.")},
               "run_error": m.get("first_error") or None,  # a failed scenario run inside the trial
               "error": None if result.error is None else str(result.error).splitlines()[0][:300]}
        trials.append(row)
    trials.sort(key=lambda r: (r["score"] if isinstance(r["score"], float) and math.isfinite(r["score"]) else math.inf))
    with open(out / "trials.parquet", "wb") as f:  # opened here: pyarrow takes only UTF-8 path names
        to_frame(trials).to_parquet(f, index=False)
    best = next((r for r in trials if r.get("feasible") is True), None)
    best_path = None
    if best is None:  # an earlier search's best.yaml is not this one's result
        (out / "best.yaml").unlink(missing_ok=True)
    else:
        cfg, _ = apply(spec.study.base, {k[2:]: v for k, v in best.items() if k.startswith("p.")})
        best_path = out / "best.yaml"
        config_mod.dump(cfg, best_path)
    return TuneOutcome(trials, best, best_path)
