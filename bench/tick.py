"""Benchmark: one full controller tick against Pinocchio's computeAllTerms on the same model.

The tick runs all four wrenches (interaction, tracking, RCM, viscous), the adaptive RCM update,
fusion, integration and the limits that keep the RCM task (motion/saturation.py), with every sensor
present and valid, once with a light hand and once with a 30 N axial push that keeps the
envelope's insertion walls active. What the saturation step costs is timed on the push run's own
saturating ticks, replayed through the compiled step (the exact QP, :func:`~lapwrench.tick_core.saturation_stage`)
and through the old per-joint clamp with the same call signature, interleaved. Everything is
timed in the same run; the ratios are the machine-independent figures. Last line: one JSON object.

The ticks run in blocks of 1000 that alternate between two settings, so both see the same machine:
``plain`` (the cyclic garbage collector on, normal scheduling) and ``loop`` (what the 1 kHz loop
does, :meth:`lapwrench.loop.ControlLoop.run` and :mod:`lapwrench.hardware.rt`: the collector frozen and
off, SCHED_FIFO when permitted). ``tick_p50_us``/``tick_p99_us`` are the ``loop`` figures, the
setting the tick runs under on a robot; ``plain_*`` are the others. computeAllTerms is timed under
the ``loop`` setting too.

The machine's own tail (``fixed_*``): after each ``loop`` tick, a fixed compiled loop that allocates nothing and
lasts about as long as the tick (:func:`fixed_work`) is timed too. Its p99 over its p50 is what the machine
does to any computation of the tick's length; a tick whose p99/p50 is no larger has no tail of its own. (On
the development VM, 2026-12-03 at load 7-8, a SCHED_FIFO loop lost the CPU for more than 20 µs 280-480
times a second, median 25-33 µs: about one 100 µs run in 25 is hit.)

    python bench/tick.py [--ticks N] [--robot panda|fr3|ur5|xarm7]
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import time
from dataclasses import dataclass, field

import numpy as np
import pinocchio as pin

from lapwrench.config import Config, load
from lapwrench.controller import Controller
from lapwrench.hardware.rt.options import RtOptions, apply_realtime
from lapwrench.jit import bind, kernel
from lapwrench.motion.reference_shaper import advance_reference
from lapwrench.robot_kinds import ROBOT_KINDS
from lapwrench.sensors import (
    ForceTorqueReading,
    InstrumentObservation,
    RobotReading,
    SensorFrame,
    TactileReading,
)
from lapwrench.tick_core import SaturationInputs, saturation_stage
from lapwrench.tick_params import TickParams
from lapwrench.virtual import home_pose


def percentiles_us(samples_ns: list[int]) -> tuple[float, float]:
    a = np.array(samples_ns) / 1e3
    return float(np.percentile(a, 50)), float(np.percentile(a, 99))


@kernel
def _clamp_stage(sat: SaturationInputs, Minv: np.ndarray, q: np.ndarray, dq: np.ndarray, p: TickParams) -> tuple:  # type: ignore[type-arg]
    """The old per-joint clamp with :func:`~lapwrench.tick_core.saturation_stage`'s signature: a_d clipped
    into the joint box, the RCM task and the envelope not kept (the reference for the step's cost)."""
    n = q.shape[0]
    ref = np.zeros((3, n))
    ref[0], ref[1], ref[2], clamped = advance_reference(q, dq, sat.a_d, sat.lo[:n], sat.hi[:n], p.dt)
    return True, ref, np.zeros(sat.lo.shape[0], dtype=np.bool_), clamped


@dataclass
class Variant:
    """One controller of the comparison, the tick times (ns) it took, and its saturating ticks' inputs."""

    ctrl: Controller
    push_n: float
    tick_ns: list[int] = field(default_factory=list)
    plain_ns: list[int] = field(default_factory=list)
    active: int = 0
    saturating: list[tuple[SaturationInputs, np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=list)


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


BLOCK = 1000  # ticks per block; the blocks alternate between the plain and the loop setting


@kernel
def fixed_work(a: np.ndarray, n: int) -> float:
    """The same arithmetic every call, in registers and ``a`` (nothing allocated): the machine's reference."""
    s = 0.0
    for k in range(n):
        for i in range(a.shape[0]):
            s += a[i] * (1.0 + 1e-9 * k)
    return s


def fixed_repeats(target_ns: float, a: np.ndarray) -> int:
    """How many repeats make :func:`fixed_work` last about ``target_ns`` (its median over a few calls)."""
    fixed_work(a, 1)
    clock = time.perf_counter_ns
    samples = []
    for _ in range(200):
        t0 = clock()
        fixed_work(a, 100)
        samples.append(clock() - t0)
    return max(1, round(100 * target_ns / float(np.median(samples))))


class LoopSetting:
    """Switch between the plain setting and the 1 kHz loop's (collector frozen and off, SCHED_FIFO
    when permitted); :attr:`problems` says what was not permitted."""

    def __init__(self) -> None:
        self.problems: list[str] = []
        self._fifo = False

    def enter(self) -> None:
        gc.collect()
        gc.freeze()
        gc.disable()
        if not self._fifo:
            self.problems = apply_realtime(RtOptions(fifo_priority=80, warn=False))
            self._fifo = not self.problems

    def leave(self) -> None:
        gc.unfreeze()
        gc.enable()
        if self._fifo:
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
            self._fifo = False


def time_interleaved(cfg: Config, ticks: int, setting: LoopSetting) -> tuple[dict[str, Variant], list[int]]:
    """Two controllers ticked in turn, so a machine that speeds up or slows down affects both alike:
    a light hand, and a 30 N axial push (the push run keeps its saturating ticks' inputs). Blocks of
    :data:`BLOCK` ticks alternate between the plain and the loop setting; each setting gets ``ticks``
    timed ticks after 1000 untimed ones. Also returns the times (ns) of :func:`fixed_work`, run after
    each ``loop`` tick of the light hand for about as long as that tick's median in the untimed block."""
    variants = {}
    for name, push in (("tick", 0.0), ("push", 30.0)):
        ctrl = Controller(cfg)
        ctrl.reset(home_pose(cfg.robot.kind))
        variants[name] = Variant(ctrl, push)
    rngs = {name: np.random.default_rng(0) for name in variants}
    tactile = TactileReading(np.full(64, 62.5))
    clock = time.perf_counter_ns
    blocks = 1 + 2 * -(-ticks // BLOCK)  # one untimed warm-up block, then plain/loop pairs
    warm_ns: list[int] = []
    fixed_ns: list[int] = []
    work, repeats = np.ones(64), 1
    for k in range(blocks * BLOCK):
        block, timed = divmod(k, BLOCK)[0], k >= BLOCK
        in_loop = block % 2 == 0
        if k % BLOCK == 0:
            setting.enter() if in_loop else setting.leave()
        if k == BLOCK:
            repeats = fixed_repeats(float(np.median(warm_ns)), work)
        for name, v in variants.items():
            frame = _frame(v, k, rngs[name], tactile)
            ref = v.ctrl.ref
            assert ref is not None
            Minv = v.ctrl.model.mass_matrix_inverse(ref.q)
            t0 = clock()
            res = v.ctrl.tick(frame)
            dt_ns = clock() - t0
            if not timed and name == "tick":
                warm_ns.append(dt_ns)
            elif timed and not in_loop:
                v.plain_ns.append(dt_ns)
            elif timed:
                v.tick_ns.append(dt_ns)
                v.active += bool(res.limits_active)
                if res.limits_active and name == "push" and len(v.saturating) < 5000:
                    sat = v.ctrl.compiled.sat  # type: ignore[union-attr]
                    v.saturating.append((SaturationInputs(*(a.copy() for a in sat)), Minv, ref.q, ref.dq))
                if name == "tick":
                    t0 = clock()
                    fixed_work(work, repeats)
                    fixed_ns.append(clock() - t0)
    return variants, fixed_ns


def time_steps(v: Variant, repeats: int) -> tuple[list[int], list[int], int]:
    """The saturation step and the per-joint clamp on the same recorded inputs, interleaved (ns each);
    and how many of the recorded ticks the compiled step solved."""
    p = v.ctrl.params
    first = v.saturating[0]
    step = bind(saturation_stage, first[0], first[1], first[2], first[3], p)
    clamp = bind(_clamp_stage, first[0], first[1], first[2], first[3], p)
    step_ns: list[int] = []
    clamp_ns: list[int] = []
    clock = time.perf_counter_ns
    solved = sum(bool(step(sat, Minv, q, dq, p)[0]) for sat, Minv, q, dq in v.saturating)
    for _ in range(repeats):
        for sat, Minv, q, dq in v.saturating:
            t0 = clock()
            step(sat, Minv, q, dq, p)
            t1 = clock()
            clamp(sat, Minv, q, dq, p)
            t2 = clock()
            step_ns.append(t1 - t0)
            clamp_ns.append(t2 - t1)
    return step_ns, clamp_ns, solved


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--ticks", type=int, default=20000)
    ap.add_argument("--robot", default="panda", choices=ROBOT_KINDS)
    args = ap.parse_args()
    if args.ticks < 100:
        ap.error("--ticks must be at least 100")

    cfg = load().replace(robot={"kind": args.robot})
    setting = LoopSetting()
    try:
        _run(args, cfg, setting)
    finally:
        setting.leave()


def _run(args: argparse.Namespace, cfg: Config, setting: LoopSetting) -> None:
    variants, fixed_ns = time_interleaved(cfg, args.ticks, setting)
    setting.enter()  # computeAllTerms and the saturation replays under the loop's setting
    ctrl = variants["tick"].ctrl
    tick_ns, push_ns = variants["tick"].tick_ns, variants["push"].tick_ns
    push_active = variants["push"].active / len(push_ns)
    recorded = variants["push"].saturating
    if not recorded:
        raise SystemExit("bench/tick.py: the push run never reached a limit; nothing to time the saturation on")
    step_ns, clamp_step_ns, solved = time_steps(variants["push"], max(1, 20000 // len(recorded)))
    model, data = ctrl.model.model, ctrl.model.data
    clock = time.perf_counter_ns
    cat_ns: list[int] = []
    q = home_pose(args.robot)
    v = 0.1 * np.ones(q.shape[0])
    for k in range(args.ticks + 1000):
        t0 = clock()
        pin.computeAllTerms(model, data, q, v)
        dt_ns = clock() - t0
        if k >= 1000:
            cat_ns.append(dt_ns)

    tick50, tick99 = percentiles_us(tick_ns)
    plain50, plain99 = percentiles_us(variants["tick"].plain_ns)
    cat50, cat99 = percentiles_us(cat_ns)
    fixed50, fixed99 = percentiles_us(fixed_ns)
    push50, push99 = percentiles_us(push_ns)
    step50, step99 = percentiles_us(step_ns)
    cstep50, cstep99 = percentiles_us(clamp_step_ns)
    added = step99 - cstep99
    fifo = "SCHED_FIFO 80" if not setting.problems else "normal scheduling (" + "; ".join(setting.problems)[:80] + ")"
    print(f"robot: {args.robot}, ticks: {len(tick_ns)} per setting; loop setting: collector frozen, {fifo}")
    print(f"controller tick      p50 {tick50:8.1f} us   p99 {tick99:8.1f} us (loop setting)")
    print(f"controller tick      p50 {plain50:8.1f} us   p99 {plain99:8.1f} us (plain: collector on, normal sched.)")
    print(f"computeAllTerms      p50 {cat50:8.1f} us   p99 {cat99:8.1f} us")
    print(f"ratio tick/CAT       p50 {tick50 / cat50:8.1f} x    p99 {tick99 / cat99:8.1f} x")
    print(f"fixed workload       p50 {fixed50:8.1f} us   p99 {fixed99:8.1f} us"
          " (allocates nothing, about the tick's length: the machine's tail)")
    print(f"p99 / p50            tick {tick99 / tick50:5.2f}    fixed workload {fixed99 / fixed50:5.2f}")
    print(f"30 N axial push      p50 {push50:8.1f} us   p99 {push99:8.1f} us ({push_active:.0%} of ticks at a limit)")
    print(f"saturation step      p50 {step50:8.1f} us   p99 {step99:8.1f} us on {len(recorded)} recorded pushing ticks"
          f" ({solved} solved compiled, the rest left to Python)")
    print(f"per-joint clamp      p50 {cstep50:8.1f} us   p99 {cstep99:8.1f} us (same inputs, same call)")
    print(f"saturation adds      p99 {added:8.1f} us (target <= 50 us); the push tick p99 is {push99 - tick99:+.1f} us"
          " over the light hand's")
    print(
        json.dumps(
            {
                "robot": args.robot,
                "sched_fifo": not setting.problems,
                "tick_p50_us": round(tick50, 2),
                "tick_p99_us": round(tick99, 2),
                "plain_tick_p50_us": round(plain50, 2),
                "plain_tick_p99_us": round(plain99, 2),
                "compute_all_terms_p50_us": round(cat50, 2),
                "compute_all_terms_p99_us": round(cat99, 2),
                "tick_over_cat_p50_x": round(tick50 / cat50, 2),
                "tick_over_cat_p99_x": round(tick99 / cat99, 2),
                "fixed_p50_us": round(fixed50, 2),
                "fixed_p99_us": round(fixed99, 2),
                "push_tick_p50_us": round(push50, 2),
                "push_tick_p99_us": round(push99, 2),
                "push_limit_active_fraction": round(push_active, 3),
                "step_p50_us": round(step50, 2),
                "step_p99_us": round(step99, 2),
                "clamp_step_p99_us": round(cstep99, 2),
                "step_solved_compiled_fraction": round(solved / len(recorded), 4),
                "saturation_added_p99_us": round(added, 2),
            }
        )
    )

if __name__ == "__main__":
    main()
