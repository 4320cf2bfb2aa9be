"""Benchmark: how a sweep scales on Ray and what Ray costs per run (issue 14).

The same jobs run three ways in one run of this script:

1. **direct**: one after another in this process, no Ray (:func:`lapwrench.study.execute.run_job`, the
   code a Ray task runs), after one warm-up job, so imports and the numba cache are already loaded;
2. **Ray, 1 worker**: ``run_study`` on an embedded Ray with 1 CPU, from ``ray.init`` to ``ray.shutdown``;
3. **Ray, 2 workers**: the same with 2 CPUs.

A job is ``rcm-disturbance`` at time scale 10/12: its two runs (with and without adaptation) are each a
10-second scenario. Throughput is jobs per wall second; Ray's overhead per run is
``(Ray 1-worker wall - direct wall) / runs``, so it includes Ray's start, the worker's start and
imports (spread over the runs) and every task's round trip, against a 10-second scenario's wall time.

    python bench/sweep.py [--jobs N]

Ray's own start (``ray.init`` to ``ray.shutdown`` with no task) is measured alone too, and the overhead
and the throughput ratio are also given without it: a long study pays it once.

Targets (issue 14): 2 workers give >= 1.8x the throughput of 1; Ray's overhead per run <= 5 % of a
10-second scenario. Last line: one JSON object.
"""

from __future__ import annotations

import os

for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")  # as in every Ray worker (lapwrench.study.runner.WORKER_ENV)
os.environ.setdefault("MUJOCO_GL", "egl")

import argparse  # noqa: E402
import json  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from lapwrench.study.execute import run_job  # noqa: E402
from lapwrench.study.runner import run_study  # noqa: E402
from lapwrench.study.spec import StudySpec, expand, from_dict  # noqa: E402

TIME_SCALE = 10.0 / 12.0  # rcm-disturbance runs max(6, 12 x scale) s: 10 s
RUNS_PER_JOB = 2


def study(jobs: int) -> StudySpec:
    return from_dict({"name": "bench", "scenarios": ["rcm-disturbance"], "seeds": {"start": 1000, "count": jobs},
                      "time_scale": TIME_SCALE, "detector": "projected"})


def direct(spec: StudySpec) -> float:
    """Wall seconds for every job of ``spec`` in this process, after a warm-up job."""
    warm = from_dict({"name": "warm", "scenarios": ["rcm-disturbance"], "seeds": [999], "time_scale": 0.05})
    run_job(expand(warm)[0], "warm")
    t0 = time.perf_counter()
    for job in expand(spec):
        rows = run_job(job, spec.name)
        assert all(r["status"] == "ok" for r in rows), rows
    return time.perf_counter() - t0


def on_ray(spec: StudySpec, workers: int) -> float:
    """Wall seconds of ``run_study`` with an embedded Ray of ``workers`` CPUs (start and shutdown included)."""
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        outcome, _ = run_study(spec, Path(tmp), workers=workers, progress=False)
        wall = time.perf_counter() - t0
    assert outcome.ran == len(expand(spec)) and outcome.failed == 0, outcome
    return wall


def ray_start_stop() -> float:
    """Wall seconds to start an embedded Ray with 1 CPU and shut it down, with no task."""
    import ray

    from lapwrench.study.runner import start_ray

    t0 = time.perf_counter()
    start_ray(None, 1)
    ray.shutdown()
    return time.perf_counter() - t0


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--jobs", type=int, default=8, help="jobs per measurement (default 8; even, >= 2)")
    args = p.parse_args()
    if args.jobs < 2 or args.jobs % 2:
        p.error("--jobs must be an even number >= 2")
    spec = study(args.jobs)
    runs = args.jobs * RUNS_PER_JOB
    d = direct(spec)
    print(f"direct, no Ray:   {args.jobs} jobs in {d:6.1f} s ({d / runs:.2f} s per 10-second run)", flush=True)
    r1 = on_ray(spec, 1)
    print(f"Ray, 1 worker:    {args.jobs} jobs in {r1:6.1f} s", flush=True)
    r2 = on_ray(spec, 2)
    print(f"Ray, 2 workers:   {args.jobs} jobs in {r2:6.1f} s", flush=True)
    boot = ray_start_stop()
    print(f"Ray start + shutdown alone: {boot:.1f} s", flush=True)
    speedup = r1 / r2
    overhead = (r1 - d) / runs
    fraction = overhead / (d / runs)
    steady = (r1 - boot - d) / runs  # without the cluster's own start, which a long study pays once
    steady_speedup = (r1 - boot) / (r2 - boot)
    print(f"throughput 2 workers / 1 worker: {speedup:.2f}x (target >= 1.8x); without Ray's own start "
          f"(paid once per study): {steady_speedup:.2f}x")
    print(f"Ray overhead per run: {overhead * 1e3:.0f} ms = {fraction:.1%} of a 10-second scenario's "
          f"{d / runs:.2f} s (target <= 5 %); without Ray's own start: {steady * 1e3:.0f} ms = "
          f"{steady / (d / runs):.1%}")
    print(json.dumps({
        "jobs": args.jobs,
        "runs": runs,
        "run_sim_s": 10.0,
        "direct_run_wall_s": round(d / runs, 3),
        "ray_1_worker_wall_s": round(r1, 2),
        "ray_2_workers_wall_s": round(r2, 2),
        "throughput_2_over_1_ratio": round(speedup, 3),
        "throughput_2_over_1_without_start_ratio": round(steady_speedup, 3),
        "ray_overhead_per_run_ms": round(overhead * 1e3, 1),
        "ray_overhead_fraction_of_10s_run": round(fraction, 4),
        "ray_start_stop_s": round(boot, 2),
        "ray_overhead_without_start_per_run_ms": round(steady * 1e3, 1),
        "ray_overhead_without_start_fraction_of_10s_run": round(steady / (d / runs), 4),
    }))


if __name__ == "__main__":
    main()
