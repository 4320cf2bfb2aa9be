"""Benchmark: the 1 kHz control loop against franky-sim, over pylibfranka, on 127.0.0.1.

Runs the full controller (scripted hand force and grip in latest-value buffers, supervisor, the
real libfranka protocol) for ``--seconds`` of robot time and prints, beside each other:

* the loop's cycle time (the period between two ``readOnce`` returns) p50/p99,
* the compute time per cycle (readOnce return → command ready) p50/p99,
* deadline misses (compute time over ``--budget-us``),
* franky-sim's own step time (its commands + physics + state send), measured in its process in
  the same run, and its real-time factor.

franky-sim is a Python server on the same two cores, so the cycle time here is bounded by its
pace, not by the controller; a real Franka sets a hard 1 ms cycle. The last line is one JSON
object with unit-suffixed keys.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import threading
import time

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="robot seconds to run (>= 10 for the report)")
    ap.add_argument("--budget-us", type=float, default=800.0, help="compute-time budget per cycle (us)")
    a = ap.parse_args()

    from lapwrench.config import load
    from lapwrench.controller import Controller
    from lapwrench.drivers.buffer import LatestValue
    from lapwrench.drivers.ft import Wrench
    from lapwrench.drivers.tactile import TactileFrame
    from lapwrench.hardware.franka import FrankaRobot
    from lapwrench.hardware.frankysim import FrankySimServer, frankysim_available
    from lapwrench.hardware.runner import ControlLoop, Sources
    from lapwrench.hardware.supervisor import SafetySupervisor, SupervisorConfig
    from lapwrench.virtual import DEFAULT_Q0

    missing = frankysim_available()
    if missing:
        print(f"bench/loop.py: franky-sim/pylibfranka unavailable: {missing}", file=sys.stderr)
        return 2
    cfg = load().replace(robot={"kind": "fr3"})
    ft: LatestValue[Wrench] = LatestValue("ft")
    tactile: LatestValue[TactileFrame] = LatestValue("tactile")
    stop = threading.Event()
    t0 = time.monotonic()

    def feed() -> None:  # the handle: slow lateral push cycles with a firm grip, 500 Hz
        while not stop.is_set():
            t = time.monotonic() - t0
            f = np.array([8.0 * np.sin(0.5 * t), 6.0 * np.sin(0.3 * t), 0.0])
            ft.put(Wrench(f, np.zeros(3)))
            tactile.put(TactileFrame(np.full(64, 40, dtype=np.uint8)))
            stop.wait(0.002)

    feeder = threading.Thread(target=feed, daemon=True)
    server = FrankySimServer(DEFAULT_Q0)
    try:
        server.start()
        feeder.start()
        ctrl = Controller(cfg)
        sup = SafetySupervisor(
            ctrl.model.limits,
            cfg.robot.dt,
            SupervisorConfig(cycle_budget=a.budget_us * 1e-6, max_consecutive_misses=0),
        )
        robot = FrankaRobot("127.0.0.1", kind="fr3", realtime="ignore", report_external_force=False)
        loop = ControlLoop(robot, ctrl, sup, Sources(ft=ft, tactile=tactile))
        loop.start()
        stats = loop.run(a.seconds)
    finally:
        stop.set()
        server.stop()
    fs = server.stats
    res = {
        **stats.summary(),
        "deadline_budget_us": a.budget_us,
        "frankysim_step_p50_us": None if fs is None else round(fs.p50_us, 1),
        "frankysim_step_p99_us": None if fs is None else round(fs.p99_us, 1),
        "frankysim_realtime_factor_x": None if fs is None else round(fs.realtime_factor, 3),
    }
    fsp50 = res["frankysim_step_p50_us"]
    fsp99 = res["frankysim_step_p99_us"]
    print(f"robot time {res['robot_time_s']} s in {res['wall_time_s']} s wall, {res['cycles']} cycles")
    cyc = f"cycle   p50 {res['cycle_p50_us']:>9} us  p99 {res['cycle_p99_us']:>9} us"
    comp = f"compute p50 {res['compute_p50_us']:>9} us  p99 {res['compute_p99_us']:>9} us"
    print(f"{cyc}   | franky-sim step p50 {fsp50} us")
    print(f"{comp}   | franky-sim step p99 {fsp99} us")
    print(
        f"deadline misses (> {a.budget_us:.0f} us) {res['deadline_misses']} of {res['cycles']}"
        f"   | franky-sim real-time factor {res['frankysim_realtime_factor_x']}"
    )
    print(json.dumps(res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
