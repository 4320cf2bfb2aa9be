"""Benchmark: one full controller tick against Pinocchio's computeAllTerms on the same model.

The tick runs all four wrenches (interaction, tracking, RCM, viscous), the adaptive RCM update,
fusion, integration and the limit shaper, with every sensor present and valid. Both are timed in
the same run; the ratio is the machine-independent figure. Last line: one JSON object.

    python bench/tick.py [--ticks N] [--robot panda|fr3]
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import pinocchio as pin

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.sensors import (
    ForceTorqueReading,
    InstrumentObservation,
    RobotReading,
    SensorFrame,
    TactileReading,
)
from lapwrench.virtual import DEFAULT_Q0


def percentiles_us(samples_ns: list[int]) -> tuple[float, float]:
    a = np.array(samples_ns) / 1e3
    return float(np.percentile(a, 50)), float(np.percentile(a, 99))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--ticks", type=int, default=20000)
    ap.add_argument("--robot", default="panda", choices=["panda", "fr3"])
    args = ap.parse_args()

    cfg = load().replace(robot={"kind": args.robot})
    ctrl = Controller(cfg)
    ctrl.reset(DEFAULT_Q0)
    rng = np.random.default_rng(0)
    tactile = TactileReading(np.full(64, 62.5))
    clock = time.perf_counter_ns

    # warm up, then time ticks with a moving hand force, a moving instrument and a residual force
    tick_ns: list[int] = []
    for k in range(args.ticks + 1000):
        t = k * ctrl.dt
        frame = SensorFrame(
            t,
            ForceTorqueReading(np.array([4.0 * np.sin(t), 3.0, 0.5]) + 0.05 * rng.standard_normal(3), np.zeros(3), t),
            tactile,
            InstrumentObservation(np.array([[480.0 + 50 * np.sin(t), 300.0], [150.0, 200.0]]), t),
            RobotReading(ctrl.ref.q, ctrl.ref.dq, np.array([7.0, 0.0, 0.0]), t),
        )
        t0 = clock()
        ctrl.tick(frame)
        dt_ns = clock() - t0
        if k >= 1000:
            tick_ns.append(dt_ns)

    model, data = ctrl.model.model, ctrl.model.data
    cat_ns: list[int] = []
    q = DEFAULT_Q0.copy()
    v = 0.1 * np.ones(7)
    for k in range(args.ticks + 1000):
        t0 = clock()
        pin.computeAllTerms(model, data, q, v)
        dt_ns = clock() - t0
        if k >= 1000:
            cat_ns.append(dt_ns)

    tick50, tick99 = percentiles_us(tick_ns)
    cat50, cat99 = percentiles_us(cat_ns)
    print(f"robot: {args.robot}, ticks: {args.ticks}")
    print(f"controller tick      p50 {tick50:8.1f} us   p99 {tick99:8.1f} us")
    print(f"computeAllTerms      p50 {cat50:8.1f} us   p99 {cat99:8.1f} us")
    print(f"ratio tick/CAT       p50 {tick50 / cat50:8.1f} x    p99 {tick99 / cat99:8.1f} x")
    print("target: tick p99 <= 100 us, i.e. <= 20x computeAllTerms")
    print(
        json.dumps(
            {
                "robot": args.robot,
                "tick_p50_us": round(tick50, 2),
                "tick_p99_us": round(tick99, 2),
                "compute_all_terms_p50_us": round(cat50, 2),
                "compute_all_terms_p99_us": round(cat99, 2),
                "tick_over_cat_p50_x": round(tick50 / cat50, 2),
                "tick_over_cat_p99_x": round(tick99 / cat99, 2),
            }
        )
    )


if __name__ == "__main__":
    main()
