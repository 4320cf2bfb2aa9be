"""Benchmark: one full controller tick against Pinocchio's computeAllTerms on the same model.

The tick runs all four wrenches (interaction, tracking, RCM, viscous), the adaptive RCM update,
fusion, integration and the limits that keep the RCM task (motion/saturation.py), with every sensor
present and valid. The same ticks are timed with the old per-joint clamp in place of the saturation
step, once with a light hand and once with a 30 N axial push that keeps the envelope's insertion
walls active, to show what the saturation costs. Everything is timed in the same run; the ratios
are the machine-independent figures. Last line: one JSON object.

    python bench/tick.py [--ticks N] [--robot panda|fr3]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from lapwrench.config import Config, load
from lapwrench.controller import Controller
from lapwrench.motion.saturation import SaturationResult
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


def _per_joint_clamp(ctrl: Controller) -> None:
    """Replace the saturation step by the old per-joint clamp (the reference for its cost)."""

    def clamp(r, t):  # type: ignore[no-untyped-def]
        s, n = ctrl.compiled.sat, ctrl.model.nv
        ctrl._a_lo, ctrl._a_hi = s.lo[:n].copy(), s.hi[:n].copy()
        return SaturationResult(np.clip(s.a_d, ctrl._a_lo, ctrl._a_hi), (), (), True)

    ctrl._saturate = clamp  # type: ignore[method-assign]


@dataclass
class Variant:
    """One controller of the comparison and the tick times (ns) it took."""

    ctrl: Controller
    push_n: float
    tick_ns: list[int] = field(default_factory=list)
    step_ns: list[int] = field(default_factory=list)  # the saturation step (or the clamp) alone
    active: int = 0

    def __post_init__(self) -> None:
        step = self.ctrl._saturate

        def timed(*args):  # type: ignore[no-untyped-def]
            t0 = time.perf_counter_ns()
            out = step(*args)
            self.step_ns.append(time.perf_counter_ns() - t0)
            return out

        self.ctrl._saturate = timed  # type: ignore[method-assign]


def _frame(v: Variant, k: int, rng: np.random.Generator, tactile: TactileReading) -> SensorFrame:
    """A moving hand force (plus ``push_n`` N along the shaft, alternating in and out every 3 s so the
    scope keeps moving between the depth walls), a moving instrument and a residual force."""
    ctrl = v.ctrl
    t = k * ctrl.dt
    axial = v.push_n * (1.0 if (k // 3000) % 2 == 0 else -1.0)
    force = np.array([4.0 * np.sin(t), 3.0, axial]) + 0.05 * rng.standard_normal(3)
    assert ctrl.ref is not None
    return SensorFrame(
        t,
        ForceTorqueReading(force, np.zeros(3), t),
        tactile,
        InstrumentObservation(np.array([[480.0 + 50 * np.sin(t), 300.0], [150.0, 200.0]]), t),
        RobotReading(ctrl.ref.q, ctrl.ref.dq, np.array([7.0, 0.0, 0.0]), t),
    )


def time_interleaved(cfg: Config, ticks: int) -> dict[str, Variant]:
    """Four controllers ticked in turn, so a machine that speeds up or slows down affects all alike:
    with and without the saturation step, with a light hand and with a 30 N axial push."""
    variants = {}
    for name, push, saturation in (("tick", 0.0, True), ("clamp", 0.0, False), ("push", 30.0, True),
                                   ("push_clamp", 30.0, False)):
        ctrl = Controller(cfg)
        ctrl.reset(DEFAULT_Q0)
        if not saturation:
            _per_joint_clamp(ctrl)
        variants[name] = Variant(ctrl, push)
        variants[name].step_ns.clear()
    rngs = {name: np.random.default_rng(0) for name in variants}
    tactile = TactileReading(np.full(64, 62.5))
    clock = time.perf_counter_ns
    for k in range(ticks + 1000):
        for name, v in variants.items():
            frame = _frame(v, k, rngs[name], tactile)
            t0 = clock()
            res = v.ctrl.tick(frame)
            dt_ns = clock() - t0
            if k >= 1000:
                v.tick_ns.append(dt_ns)
                v.active += bool(res.limits_active)
    return variants


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--ticks", type=int, default=20000)
    ap.add_argument("--robot", default="panda", choices=["panda", "fr3"])
    args = ap.parse_args()
    if args.ticks < 100:
        ap.error("--ticks must be at least 100")

    cfg = load().replace(robot={"kind": args.robot})
    variants = time_interleaved(cfg, args.ticks)
    ctrl = variants["tick"].ctrl
    tick_ns, clamp_ns = variants["tick"].tick_ns, variants["clamp"].tick_ns
    push_ns, push_clamp_ns = variants["push"].tick_ns, variants["push_clamp"].tick_ns
    push_active = variants["push"].active / args.ticks
    step = {name: percentiles_us(v.step_ns[1000:]) for name, v in variants.items()}
    model, data = ctrl.model.model, ctrl.model.data
    clock = time.perf_counter_ns
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
    clamp50, clamp99 = percentiles_us(clamp_ns)
    push50, push99 = percentiles_us(push_ns)
    pclamp50, pclamp99 = percentiles_us(push_clamp_ns)
    print(f"robot: {args.robot}, ticks: {args.ticks}")
    print(f"controller tick      p50 {tick50:8.1f} us   p99 {tick99:8.1f} us")
    print(f"computeAllTerms      p50 {cat50:8.1f} us   p99 {cat99:8.1f} us")
    print(f"ratio tick/CAT       p50 {tick50 / cat50:8.1f} x    p99 {tick99 / cat99:8.1f} x")
    print(f"per-joint clamp tick p50 {clamp50:8.1f} us   p99 {clamp99:8.1f} us (the old shaper, same demand)")
    print(f"30 N axial push      p50 {push50:8.1f} us   p99 {push99:8.1f} us ({push_active:.0%} of ticks at a limit)")
    print(f"  per-joint clamp    p50 {pclamp50:8.1f} us   p99 {pclamp99:8.1f} us")
    print(f"saturation adds      p99 {tick99 - clamp99:8.1f} us, {push99 - pclamp99:8.1f} us pushing (tick p99s)")
    for name, (s50, s99) in step.items():
        print(f"  step alone {name:11s} p50 {s50:8.1f} us   p99 {s99:8.1f} us")
    added = step["tick"][1] - step["clamp"][1]
    added_push = step["push"][1] - step["push_clamp"][1]
    print(f"step adds            p99 {added:8.1f} us, {added_push:8.1f} us pushing (target <= 50 us)")
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
                "clamp_tick_p99_us": round(clamp99, 2),
                "push_tick_p99_us": round(push99, 2),
                "push_clamp_tick_p99_us": round(pclamp99, 2),
                "push_limit_active_fraction": round(push_active, 3),
                "saturation_added_p99_us": round(tick99 - clamp99, 2),
                "saturation_added_push_p99_us": round(push99 - pclamp99, 2),
                "step_p99_us": round(step["tick"][1], 2),
                "step_push_p99_us": round(step["push"][1], 2),
                "clamp_step_p99_us": round(step["clamp"][1], 2),
                "step_added_p99_us": round(added, 2),
                "step_added_push_p99_us": round(added_push, 2),
            }
        )
    )


if __name__ == "__main__":
    main()
