"""Ticks of the controller on random states, written to an .npz (run by test_compiled_tick.py).

usage: python tests/compiled_ticks.py OUT.npz [--extra]"""

from __future__ import annotations

import sys

import numpy as np

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.jit import jit_enabled
from lapwrench.sensors import ForceTorqueReading, InstrumentObservation, RobotReading, SensorFrame, TactileReading
from lapwrench.spatial import Wrench
from lapwrench.wrenches.base import Cue, TickContext

POSES = 24
TICKS = 40


class PullToward(Cue):
    """An extra null-space cue: a spring of the closest point toward a fixed point (exercises the two-call tick)."""

    def compute(self, ctx: TickContext) -> Wrench:
        p = ctx.geometry.p_G
        return Wrench(np.array([0.0, 0.0, 0.05]), 20.0 * (np.array([0.4, 0.1, 0.3]) - p), p)


def random_frame(rng: np.random.Generator, t: float, q: np.ndarray) -> SensorFrame:
    """Every input present and valid, with random values (large pushes included)."""
    force = rng.uniform(-40.0, 40.0, 3)
    grip = rng.uniform(0.0, 255.0, 64) * (rng.random(64) < 0.6)
    points = rng.uniform([0.0, 0.0], [640.0, 480.0], (int(rng.integers(0, 4)), 2))
    q_meas = q + rng.normal(0.0, 2e-3, 7)
    return SensorFrame(
        t,
        ForceTorqueReading(force, rng.uniform(-1.0, 1.0, 3), t),
        TactileReading(grip, t),
        InstrumentObservation(points, t),
        RobotReading(q_meas, rng.normal(0.0, 0.05, 7), rng.uniform(-20.0, 20.0, 3), t),
    )


def main(out: str, extra: bool) -> None:
    cfg = load()
    rng = np.random.default_rng(7)
    ctrl = Controller(cfg, extra_cues=[PullToward("pull", None, cfg)] if extra else ())
    lim = ctrl.model.limits
    rows: dict[str, list[np.ndarray]] = {}
    for pose in range(POSES):
        mid = 0.5 * (lim.position_lower + lim.position_upper)
        q0 = mid + 0.4 * (lim.position_upper - lim.position_lower) * rng.uniform(-1.0, 1.0, 7) * 0.5
        ctrl.reset(q0)
        ctrl.stopping = pose % 4 == 3  # every fourth pose brakes to rest (the stopping path of the tick)
        for k in range(TICKS):
            assert ctrl.ref is not None
            r = ctrl.tick(random_frame(rng, k * ctrl.dt, ctrl.ref.q))
            values = {"q_ref": r.q_ref, "dq_ref": r.dq_ref, "tau": r.tau, "W_n": r.W_n, "e_R": r.e_R, "p_R": r.p_R,
                      "p_G": r.p_G, "delta": np.array([r.delta]), **{f"W_{n}": w for n, w in r.wrenches.items()}}
            for key, v in values.items():
                rows.setdefault(key, []).append(np.asarray(v, dtype=float))
    np.savez(out, jit=np.array([jit_enabled()]), **{k: np.array(v) for k, v in rows.items()})


if __name__ == "__main__":
    main(sys.argv[1], "--extra" in sys.argv[2:])
