"""End to end through the real libfranka protocol: pylibfranka ↔ franky-sim on 127.0.0.1, through the
process path of ``lapwrench run``, beside a CPU-heavy process.

The full controller runs in its own process (:mod:`lapwrench.hardware.rt`) for more than
5 s of robot time with a simulated handle wrench arriving through the real UDP F/T driver (a
loopback HEX box), drained by the loop's process each cycle; the grip comes through shared memory
from this process; every command goes through the supervisor and pylibfranka's ``writeOnce``, and
the checks use only what the robot *reports* (the measured joints of the logged cycles). A busy
``while True: pass`` process runs beside it the whole time (a fresh-clone CI run once lost the F/T
freshness when the machine was busy).

franky-sim, honestly:

* **Zero external wrench.** franky-sim fills ``O_F_ext_hat_K`` with zeros. Fed to the adaptive
  RCM law that would read the whole hand force as a trocar residual and walk the RCM point away.
  The robot is therefore configured with ``report_external_force=False``: the controller gets no
  force estimate and the adaptation sees no residual (p_R stays at eq 18's point), which is also
  what the controller does on a real robot whose estimate is invalid.
* **Below real time.** franky-sim is a Python process sharing two cores with the client (and
  other jobs); it paces itself with ``sleep`` and falls behind under load. Its robot time
  (``readOnce`` durations) still advances 1 ms per step, so the run is measured in robot time.
  Deadline misses are counted but do not stop the run (``max_consecutive_misses=0``); the
  deadline logic is tested on its own in ``test_supervisor.py`` and ``test_faults.py``.
* **No limit enforcement.** A real Franka aborts on a velocity/acceleration/jerk violation;
  franky-sim does not, so the test checks every sent command against the limits itself, exactly
  as libfranka differentiates them.
"""

from __future__ import annotations

import functools
import subprocess
import sys
import threading
from typing import Any

import numpy as np
import pytest
from hardware.support import MemoryLogger, Pushes, QdProbe, RobotTimeForce, pushed_force, rt_process, rt_spec

from lapwrench.buffer import LatestValue
from lapwrench.config import Config
from lapwrench.drivers.tactile import TactileFrame
from lapwrench.hardware.devices import SimulatedHexProcess
from lapwrench.hardware.frankysim import FrankySimServer
from lapwrench.hardware.rt import FtSpec, RtProcess, franka_factory
from lapwrench.robot.limits import limit_usage
from lapwrench.robot.model import RobotModel
from lapwrench.safety.supervisor import measure_scope

BOX_FIFO_PRIORITY = 70  # below the loop's own (RtOptions: 80)

pytestmark = pytest.mark.slow  # franky-sim end to end


PUSHES: Pushes = ((0.8, 2.8, (12.0, 0.0, 0.0)), (3.2, 4.8, (0.0, -10.0, 0.0)))  # lateral, pause, the other way


def hand_force(t: float) -> np.ndarray:
    """Handle force in {H} at robot time ``t`` (:data:`PUSHES`)."""
    return pushed_force(PUSHES, t)


def axis_distance(model: RobotModel, q: np.ndarray, p_R: np.ndarray) -> float:
    """Distance (m) from p_R to the scope axis at joints q: the supervisor's measured |e_R| (eq 27)."""
    return measure_scope(model, q, p_R).rcm_error


def test_full_controller_on_frankysim_holds_the_rcm(frankysim: FrankySimServer, fr3_cfg: Config) -> None:
    # The handle wrench travels the real path: loopback HEX box → UDP → the loop process's
    # OnRobotHexSensor, drained each cycle. The scripts run on robot time (the loop's cycle count,
    # published on the shared bus), not wall time: franky-sim falls behind real time under load,
    # and a wall-clock script then pushes for less robot time (a fresh-clone CI run once saw the
    # flange move 3.98 mm against the 4 mm check).
    dt = fr3_cfg.robot.dt
    tactile: LatestValue[Any] = LatestValue("tactile")
    stop = threading.Event()
    log = MemoryLogger()
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    rp: RtProcess | None = None
    try:
        factory = functools.partial(
            franka_factory, robot_ip="127.0.0.1", kind="fr3", realtime="ignore", report_external_force=False
        )
        rp = rt_process(rt_spec(fr3_cfg, robot_factory=factory, loop_hook=QdProbe), tactile=tactile, logger=log)

        def grip() -> None:
            while not stop.is_set():
                tactile.put(TactileFrame(np.full(64, 40, dtype=np.uint8)))
                stop.wait(0.005)

        threading.Thread(target=grip, daemon=True).start()
        # the box in a process of its own, its thread at SCHED_FIFO (when permitted), as bench/loop.py runs
        # it: a real box is a device with a CPU of its own, so neither the busy process nor this process's
        # threads (the grip, the log reader: they share one interpreter) may delay its records (two runs
        # beside CI and two busy processes saw 89 % fresh without the priority; 98.3-99.3 % with it, the
        # box a thread of this process)
        box = SimulatedHexProcess(
            RobotTimeForce(rp.bus_name, (rp.spec.log_rows, rp.spec.event_rows), dt, PUSHES), rate_hz=1000.0,
            fifo_priority=BOX_FIFO_PRIORITY,
        ).start()
        try:
            rp.spec.ft = FtSpec("hex", "127.0.0.1", box.port, tare=True, tare_samples=50)
            rp.start()
            res = rp.run(5.5)
        finally:
            box.close()
    finally:
        stop.set()
        busy.kill()
        busy.wait()
        if rp is not None:
            rp.close()
    stats, report = res.stats, res.report

    assert stats.robot_time >= 5.0
    assert stats.alarm is None, stats.alarm
    assert stats.stopped_at_rest
    assert report["external_force_at_connect"] is None
    assert len(log.cycles) == stats.cycles and all(c.external_force is None for c in log.cycles)
    # the hand moved the scope (the pipeline is live), through the interaction wrench
    modes = [c.mode for c in log.cycles]
    assert "handle" in modes
    # the F/T stayed fresh beside a busy process: the handle wrench was on through the pushes
    # (robot time of cycle k is (k + 1) dt, as the bus counter the box reads counts it)
    pushing = [m for i, m in enumerate(modes) if np.linalg.norm(hand_force((i + 1) * dt)) > 0]
    assert pushing.count("handle") >= 0.9 * len(pushing), [e for e in rp.events if e[1] != "deadline_miss"]
    model = RobotModel("fr3")
    q = np.array([stats.q_start] + [c.q for c in log.cycles])
    # (the scope pivots about the RCM, so its handle end moves most)
    e0 = model.frame_pose(q[0], "lap_E").translation
    moves = [np.linalg.norm(model.frame_pose(qq, "lap_E").translation - e0) for qq in q[::100]]
    assert max(moves) > 0.004, f"the scope flange moved only {max(moves) * 1e3:.1f} mm"
    # RCM from the reported joints: the scope axis passes through the controller's RCM point
    # (adaptation sees no residual with franky-sim, so p_R is constant; checked here)
    p_R = stats.p_R
    assert np.allclose([c.p_R for c in log.cycles[::500]], p_R, atol=1e-9)
    errors = np.array([axis_distance(model, qq, p_R) for qq in q[::5]])
    fresh = 100.0 * report["ft_fresh_cycles"] / max(1, report["hook_cycles"])
    print(
        f"\nfranky-sim e2e (process path, busy process beside): {stats.cycles} cycles, robot"
        f" {stats.robot_time:.2f} s, wall {stats.wall_time:.2f} s; RCM error from reported joints max"
        f" {errors.max() * 1e3:.3f} mm, rms {np.sqrt(np.mean(errors**2)) * 1e3:.3f} mm; flange moved up to"
        f" {max(moves) * 1e3:.1f} mm; deadline misses {stats.deadline_misses}; F/T fresh {fresh:.2f} %"
    )
    assert errors.max() < 0.003
    # the loop drained a sample younger than the spec's max age in nearly every cycle, beside the busy process
    # (100.00 % in 7 of 7 runs on 2026-12-03 with the box a process of its own; 98.25-99.27 % with it a thread
    # of this process, which this check would catch in about half the runs)
    assert fresh >= 99.0, f"F/T fresh in {fresh:.2f} % of the cycles"
    # every command inside the Franka limits, differentiated as libfranka does, from rest
    usage = limit_usage(stats.commands, fr3_cfg.robot.dt, model.limits, stats.q_start)
    assert usage["position_excess"] == 0.0
    for k in ("velocity", "acceleration", "jerk"):
        assert usage[k] <= 1.0, usage
    # and the reported desired positions are the commands we sent (nothing altered on the way)
    assert report["q_d_last"] is not None
    # Measured 2026-12-01 with the franky-sim installed today: q_d differs from the last command by up
    # to 1.3e-6 rad, on the code before issue 9 too (it passed at 1e-9 before); 1e-5 rad still catches
    # any command altered on the way (the smallest joint step at 0.1 rad/s is 1e-4 rad).
    q_d = np.asarray(report["q_d_last"])
    assert np.allclose(q_d, stats.commands[-1], atol=1e-5), q_d - stats.commands[-1]
