"""Benchmark: how a sweep scales on Ray and what Ray costs per run (issue 14).

The same jobs run four ways in one run of this script:

1. **direct**: one after another in this process, no Ray (:func:`lapwrench.study.execute.run_job`, the
   code a Ray task runs), after one warm-up job, so imports and the numba cache are already loaded;
2. **2 plain processes, no Ray** (each imports and warms up, then both run half the jobs, started
   together and timed from there, like 1.): what this machine's two cores give two workers without
   Ray, the ceiling for the next two;
3. **Ray, 1 worker**: ``run_study`` on an embedded Ray with 1 CPU, from ``ray.init`` to ``ray.shutdown``;
4. **Ray, 2 workers**: the same with 2 CPUs.

A job is ``rcm-disturbance`` at time scale 10/12: its two runs (with and without adaptation) are each a
10-second scenario. Throughput is jobs per wall second, from the call to ``run_study`` to its return, and
in the steady state (from the first job's start to the last job's end, by the workers' clocks: what a
long study sees once Ray and its workers are up). Ray's overhead is read from the workers' own
timestamps (every row has the job's start and wall time), so the machine's speed, which drifts by 20 %
here from minute to minute, does not enter it: per run, the round trip from one job's end to the next
one's start in the 1-worker run; once per study, the time before the first job starts (Ray's start, the
worker's boot) and all the 1-worker wall time spent outside jobs.

    python bench/sweep.py [--jobs N] [--rounds R]

Direct and both Ray runs alternate in each round; the figures are medians over the rounds.

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
import statistics  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from dataclasses import dataclass  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any  # noqa: E402

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


def _job_list(seeds: list[int], barrier: Any, out: Any) -> None:
    """One of :func:`two_processes`' workers: warm up, wait for the other, run the jobs of ``seeds``, and put
    the wall seconds of those jobs on ``out``."""
    spec = from_dict({"name": "bench", "scenarios": ["rcm-disturbance"], "seeds": seeds, "time_scale": TIME_SCALE,
                      "detector": "projected"})
    warm = from_dict({"name": "warm", "scenarios": ["rcm-disturbance"], "seeds": [999], "time_scale": 0.05})
    run_job(expand(warm)[0], "warm")
    barrier.wait()
    t0 = time.perf_counter()
    for job in expand(spec):
        rows = run_job(job, "bench")
        assert all(r["status"] == "ok" for r in rows), rows
    out.put(time.perf_counter() - t0)


def two_processes(spec: StudySpec) -> float:
    """Wall seconds for the jobs of ``spec`` split over 2 plain processes (no Ray), each warmed up first
    like :func:`direct` and started together: what this machine's two cores give two workers, the ceiling
    for Ray's 2 workers. The slower half's time (start-up excluded, as in :func:`direct`)."""
    import multiprocessing as mp

    seeds = sorted({j.seed for j in expand(spec)})
    ctx = mp.get_context("spawn")
    barrier, out = ctx.Barrier(2), ctx.Queue()
    procs = [ctx.Process(target=_job_list, args=(half, barrier, out)) for half in (seeds[0::2], seeds[1::2])]
    for proc in procs:
        proc.start()
    walls = [out.get() for _ in procs]
    for proc in procs:
        proc.join()
    return max(walls)


@dataclass
class RayRun:
    wall_s: float  # run_study, from the call to its return (Ray's start and shutdown included)
    inside_s: float  # the jobs' own time inside the workers, summed
    first_start_s: float  # from the call to the first job's start in a worker (Ray start, worker boot)
    gaps_s: list[float]  # 1 worker: from one job's end to the next one's start (the per-task round trip)
    busy_s: float  # from the first job's start to the last job's end (the steady state, without start-up)


def on_ray(spec: StudySpec, workers: int) -> RayRun:
    """``run_study`` with an embedded Ray of ``workers`` CPUs, timed from outside and from the workers'
    own timestamps (``started_unix_s`` and ``wall_s`` of every job)."""
    with tempfile.TemporaryDirectory() as tmp:
        t0_unix, t0 = time.time(), time.perf_counter()
        outcome, table = run_study(spec, Path(tmp), workers=workers, progress=False)
        wall = time.perf_counter() - t0
        jobs = table.frame().drop_duplicates("run_id").sort_values("started_unix_s")
    assert outcome.ran == len(expand(spec)) and outcome.failed == 0, outcome
    starts, walls = jobs["started_unix_s"].to_numpy(), jobs["wall_s"].to_numpy()
    gaps = [float(starts[k + 1] - (starts[k] + walls[k])) for k in range(len(starts) - 1)]
    busy = float((starts + walls).max() - starts[0])
    return RayRun(wall, float(walls.sum()), float(starts[0] - t0_unix), gaps, busy)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--jobs", type=int, default=8, help="jobs per measurement (default 8; even, >= 2)")
    p.add_argument("--rounds", type=int, default=2, help="rounds of direct / Ray 1 / Ray 2, medians taken (default 2)")
    args = p.parse_args()
    if args.jobs < 2 or args.jobs % 2 or args.rounds < 1:
        p.error("--jobs must be an even number >= 2 and --rounds >= 1")
    spec = study(args.jobs)
    runs = args.jobs * RUNS_PER_JOB
    ds, ones, twos = [], [], []
    for k in range(args.rounds):
        ds.append(direct(spec))
        ones.append(on_ray(spec, 1))
        twos.append(on_ray(spec, 2))
        one, two = ones[-1], twos[-1]
        print(f"round {k + 1}: direct {ds[-1]:6.1f} s; Ray 1 worker {one.wall_s:6.1f} s "
              f"(jobs inside {one.inside_s:6.1f} s, first job began after {one.first_start_s:.1f} s, "
              f"median gap between jobs {statistics.median(one.gaps_s) * 1e3:.0f} ms); "
              f"Ray 2 workers {two.wall_s:6.1f} s", flush=True)
    d = statistics.median(ds)
    r1, r2 = (statistics.median(r.wall_s for r in rs) for rs in (ones, twos))
    first = statistics.median(r.first_start_s for r in ones)
    gap = statistics.median(g for r in ones for g in r.gaps_s)
    fixed = statistics.median(r.wall_s - r.inside_s for r in ones)  # everything that is not a job's own time
    p2 = two_processes(spec)
    print(f"2 processes, no Ray (warmed up, started together): {p2:6.1f} s ({d / p2:.2f}x direct)", flush=True)
    run_s = d / runs
    per_run = gap / RUNS_PER_JOB  # a job holds two 10-second runs
    speedup = r1 / r2
    b1, b2 = (statistics.median(r.busy_s for r in rs) for rs in (ones, twos))
    steady = b1 / b2
    print(f"medians of {args.rounds} rounds, {args.jobs} jobs ({runs} runs of 10 s simulated, {run_s:.2f} s each):")
    print(f"throughput 2 workers / 1 worker: {speedup:.2f}x from the call to the return (target >= 1.8x); "
          f"{steady:.2f}x in the steady state (first job's start to last job's end: {b1:.1f} s / {b2:.1f} s); "
          f"two plain processes, no Ray, in the same run: {d / p2:.2f}x one (the machine's ceiling)")
    print(f"Ray's overhead per run (round trip between two jobs in the 1-worker run, per 10-second run): "
          f"{per_run * 1e3:.1f} ms = {per_run / run_s:.2%} of a run (target <= 5 %)")
    print(f"once per study: {first:.1f} s before the first job starts (Ray's start, the worker's boot), "
          f"{fixed:.1f} s of the 1-worker wall outside the jobs in all ({fixed / runs * 1e3:.0f} ms per run over "
          f"{runs} runs = {fixed / runs / run_s:.1%})")
    print(json.dumps({
        "jobs": args.jobs,
        "runs": runs,
        "rounds": args.rounds,
        "run_sim_s": 10.0,
        "direct_run_wall_s": round(run_s, 3),
        "ray_1_worker_wall_s": round(r1, 2),
        "ray_2_workers_wall_s": round(r2, 2),
        "two_processes_no_ray_over_one_ratio": round(d / p2, 3),
        "throughput_2_over_1_ratio": round(speedup, 3),
        "throughput_2_over_1_steady_ratio": round(steady, 3),
        "ray_gap_between_jobs_ms": round(gap * 1e3, 2),
        "ray_overhead_per_run_ms": round(per_run * 1e3, 2),
        "ray_overhead_per_run_fraction": round(per_run / run_s, 5),
        "ray_first_job_start_s": round(first, 2),
        "ray_outside_jobs_per_study_s": round(fixed, 2),
        "ray_outside_jobs_per_run_fraction": round(fixed / runs / run_s, 4),
    }))


if __name__ == "__main__":
    main()
