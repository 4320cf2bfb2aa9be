"""Benchmark: the 1 kHz control loop in its own process against franky-sim, idle and loaded.

The loop runs as ``lapwrench run`` runs it (:mod:`lapwrench.hardware.rt`): a spawned
process with the robot (pylibfranka → franky-sim on 127.0.0.1), the full controller and the
supervisor, draining the handle F/T socket each cycle (a simulated HEX box streaming 1 kHz UDP from
a process of its own, as a real box is a device of its own). This process feeds the tactile grip
through shared memory, drains the log ring and waits. Two runs of ``--seconds`` robot seconds:

* ``idle``: nothing else of ours running;
* ``loaded``: a pure-Python busy thread in *this* (the parent) process, plus the detector process
  running the shipped ONNX detector (two passes, 1 thread) at 25 fps on synthetic frames
  (:func:`lapwrench.perception.synthetic.draw_instrument_scene`) published by this process through
  the shared frame slot, its points going to the loop (``--detector classical`` swaps it);
* ``live``: as idle, with the cycle records shipped to this process and served live to Foxglove
  (``run --foxglove``: :class:`~lapwrench.hardware.log.RunLogger` with a WebSocket server, no file)
  and a WebSocket client subscribed to every channel: what live telemetry costs the loop.

Per run: compute time (``readOnce`` return → command ready) p50/p99, the controller tick's own
p50/p99 and its share of the compute time; the real-time process's hooks (F/T drain, shared inputs,
peer watch), which run after the command in the cycle's slack, p50/p99, and each cycle's busy time
(compute + the hooks after the previous command) p99; deadline misses (the supervisor's: its busy time,
the compute plus all the loop's work from the previous command's return to this state read, hooks, the
run log and the run's bookkeeping included, over ``--budget-us``; ``compute_misses``: compute alone over
it, the rule before 2026-12-03) and the
longest run of consecutive misses, the F/T sample fresh fraction (the newest F/T sample at most
20 ms old when the cycle reads it), the detector's frame rate, franky-sim's own step time and its
real-time factor. franky-sim is a Python server on the same two cores, so the *cycle* time is
bounded by its pace, not by the controller; a real Franka sets a hard 1 ms cycle. The last line is
one JSON object with unit-suffixed keys.

Where the busy time goes (:func:`phases`, from each cycle's read and command stamps): the wait in
``readOnce``, the command's own time, the tail from the command's return to the next read (the hooks,
the log, the run's bookkeeping), the busy time recomputed as the loop counts it (``busy_full_*``), each
miss put down to the part furthest above its median (``misses_led_by``: the tick, the rest of the
compute, the filter, the hooks, the rest of the tail), and the misses whose state came more than
5 ms late (``misses_after_a_late_state``: franky-sim stalled, and the loop caught up on the F/T socket
before its tick). The loop thread's page faults and involuntary switches are counted inside the
cycling only. ``--lock-memory`` (on by default, as ``lapwrench run``) locks the loop's memory;
``--rt-cpus 1 --others-cpus 0`` leaves CPU 1 to the loop and puts franky-sim, the F/T box, this process
and the detector on CPU 0.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import os
import resource
import sys
import threading
import time
from typing import Any

import numpy as np

os.environ.setdefault("MUJOCO_GL", "egl")


def hand_force(t: float) -> np.ndarray:
    """The handle: slow lateral push cycles (N, in {H})."""
    if not np.isfinite(t):
        return np.zeros(3)
    return np.array([8.0 * np.sin(0.5 * t), 6.0 * np.sin(0.3 * t), 0.0])


class TickTimer:
    """Installed in the real-time child (``RtSpec.loop_hook``): times ``controller.tick``, stamps each cycle's
    read (call, return) and command (call, return), and counts the loop thread's page faults and involuntary
    context switches from its first cycle to its last thousandth (its start and end left out)."""

    N = 200_000

    def __init__(self, loop: Any) -> None:
        self.times = np.zeros(self.N)
        self.n = 0
        self.stamps = np.zeros((self.N, 4))  # perf_counter: read call, read return, command call, command return
        self.k = 0
        self.usage: list[Any] = []  # the thread's rusage at the first cycle, then at every thousandth
        tick, robot = loop.controller.tick, loop.robot
        read, command = robot.read, robot.command
        perf, usage, thread = time.perf_counter, resource.getrusage, resource.RUSAGE_THREAD

        def timed(frame: Any) -> Any:
            t0 = perf()
            try:
                return tick(frame)
            finally:
                if self.n < self.times.size:
                    self.times[self.n] = perf() - t0
                    self.n += 1

        def timed_read() -> Any:
            k = self.k
            if k % 1000 == 1:
                self.usage[1:] = [usage(thread)] if self.usage else []
                if not self.usage:
                    self.usage.append(usage(thread))
            if k < self.N:
                self.stamps[k, 0] = perf()
            out = read()
            if k < self.N:
                self.stamps[k, 1] = perf()
            self.k = k + 1
            return out

        def timed_command(q: Any, **kw: Any) -> Any:
            k = self.k - 1
            if 0 <= k < self.N:
                self.stamps[k, 2] = perf()
            try:
                return command(q, **kw)
            finally:
                if 0 <= k < self.N:
                    self.stamps[k, 3] = perf()

        loop.controller.tick = timed
        robot.read, robot.command = timed_read, timed_command
        self.faults = resource.getrusage(resource.RUSAGE_SELF)  # from here on: the run (warm-up done)

    def report(self) -> dict[str, Any]:
        now = resource.getrusage(resource.RUSAGE_SELF)
        u = self.usage
        in_cycles = {} if len(u) < 2 else {
            "faults_in_cycles": (u[1].ru_minflt - u[0].ru_minflt, u[1].ru_majflt - u[0].ru_majflt),
            "involuntary_switches_in_cycles": u[1].ru_nivcsw - u[0].ru_nivcsw,
        }
        return {"tick_us": (self.times[: self.n] * 1e6).tolist(), "major_faults": now.ru_majflt - self.faults.ru_majflt,
                "minor_faults": now.ru_minflt - self.faults.ru_minflt, "cycle_stamps": self.stamps[: self.k].copy(),
                **in_cycles}


def phases(
    comp: np.ndarray, tick: np.ndarray, hook: np.ndarray, stamps: np.ndarray, budget: float, late: float
) -> dict[str, Any]:
    """Each cycle's busy time as the loop counts it, from the stamps: its compute, then the filter before the
    previous command and the tail after it (the hooks, the log, the run's bookkeeping) until this read. The
    cycles over ``budget``, each put down to the part furthest above its own median, and those whose state
    came ``late`` after the read was called (franky-sim stalled; the loop catches up on the F/T socket in its
    compute). All in µs."""
    n = min(comp.size, len(stamps) - 1, hook.size - 1)  # the last cycle's command is the disconnect's
    if n < 3:
        return {}
    sp, c = stamps[:n] * 1e6, comp[:n]
    read_wait, command = sp[:, 1] - sp[:, 0], sp[:, 3] - sp[:, 2]
    filt = sp[:-1, 2] - sp[:-1, 1] - c[:-1]  # read return to command call, less the compute: the filter
    tail = sp[1:, 0] - sp[:-1, 3]  # command return to the next read call
    hooks = hook[1:n]  # hook[0] ran before the first cycle
    busy = c[1:] + filt + tail
    t = tick[1:n] if tick.size >= n else np.zeros(n - 1)
    parts = {"tick": t, "compute_other": c[1:] - t, "filter": filt, "hooks": hooks, "tail_other": tail - hooks}
    excess = np.stack([v - np.median(v) for v in parts.values()])
    miss = busy > budget
    led = np.asarray(list(parts))[np.argmax(excess, axis=0)][miss]
    return {
        "read_wait_p50_us": round(float(np.median(read_wait)), 1),
        "command_p50_us": round(float(np.median(command)), 1),
        "command_p99_us": round(float(np.percentile(command, 99)), 1),
        "tail_p50_us": round(float(np.median(tail)), 1),
        "tail_p99_us": round(float(np.percentile(tail, 99)), 1),
        "busy_full_p99_us": round(float(np.percentile(busy, 99)), 1),
        "busy_full_misses": int(miss.sum()),
        "misses_led_by": {k: int((led == k).sum()) for k in parts},
        "misses_after_a_late_state": int((miss & (read_wait[1:] > late)).sum()),
    }


def longest_run(mask: np.ndarray) -> int:
    best = cur = 0
    for m in mask:
        cur = cur + 1 if m else 0
        best = max(best, cur)
    return best


class LiveClient:
    """A Foxglove WebSocket client in a thread: subscribes to every advertised channel, counts what arrives."""

    def __init__(self, port: int) -> None:
        self.port, self.messages, self.bytes = port, 0, 0
        self.stop = threading.Event()
        self.thread = threading.Thread(target=lambda: __import__("asyncio").run(self._run()), daemon=True)
        self.thread.start()

    async def _run(self) -> None:
        import asyncio

        import websockets

        async with websockets.connect(f"ws://127.0.0.1:{self.port}", subprotocols=["foxglove.sdk.v1"],
                                      max_size=None) as ws:
            subscribed: set[int] = set()
            while not self.stop.is_set():
                try:
                    msg = await asyncio.wait_for(ws.recv(), 0.1)
                except TimeoutError:
                    continue
                if isinstance(msg, str):
                    op = json.loads(msg)
                    if op.get("op") == "advertise":
                        new = [c["id"] for c in op["channels"] if c["id"] not in subscribed]
                        subscribed.update(new)
                        await ws.send(json.dumps({"op": "subscribe",
                                                  "subscriptions": [{"id": i, "channelId": i} for i in new]}))
                elif msg and msg[0] == 0x01:
                    self.messages += 1
                    self.bytes += len(msg)

    def close(self) -> None:
        self.stop.set()
        self.thread.join(2.0)


def one_run(name: str, a: argparse.Namespace, loaded: bool, live: bool = False) -> dict[str, Any]:
    from lapwrench.buffer import LatestValue
    from lapwrench.config import load
    from lapwrench.drivers.tactile import TactileFrame
    from lapwrench.hardware.cli import SimulatedHexProcess
    from lapwrench.hardware.frankysim import FrankySimServer
    from lapwrench.hardware.rt import FtSpec, RtOptions, RtProcess, RtSpec, franka_factory
    from lapwrench.hardware.rt.child import FT_CATCH_UP_S
    from lapwrench.safety.supervisor import SupervisorConfig
    from lapwrench.virtual import DEFAULT_Q0

    cfg = load().replace(robot={"kind": "fr3"})
    tactile: LatestValue[TactileFrame] = LatestValue("tactile")
    stop = threading.Event()
    threads: list[threading.Thread] = []
    closers: list[Any] = []

    def feed_tactile() -> None:  # the tactile reader's buffer: a firm grip, 200 Hz
        while not stop.is_set():
            tactile.put(TactileFrame(np.full(64, 40, dtype=np.uint8)))
            stop.wait(0.005)

    server = FrankySimServer(DEFAULT_Q0)
    det = None
    try:
        server.start()
        closers.append(server.stop)
        fake = SimulatedHexProcess(hand_force, rate_hz=1000.0, fifo_priority=a.ft_box_priority or None).start()
        closers.append(fake.close)
        if a.frankysim_nice:  # every thread of it: its steps at a higher share of a busy machine's CPUs
            for tid in os.listdir(f"/proc/{server.pid}/task"):
                with contextlib.suppress(ProcessLookupError):
                    os.setpriority(os.PRIO_PROCESS, int(tid), a.frankysim_nice)
        others = _cpus(a.others_cpus)
        if others is not None:  # franky-sim, the F/T box and this process (its threads, and what it spawns next)
            for pid in (server.pid, fake.proc.pid, os.getpid()):
                _pin(pid, others)
        spec = RtSpec(
            cfg=cfg,
            robot_factory=functools.partial(
                franka_factory, robot_ip="127.0.0.1", kind="fr3", realtime="ignore", report_external_force=False
            ),
            supervisor=SupervisorConfig.from_config(cfg, cycle_budget=a.budget_us * 1e-6, max_consecutive_misses=0),
            ft=FtSpec("hex", "127.0.0.1", fake.port, tare=False),
            tactile=True,
            instruments=loaded,
            log_cycles=live,
            rt=RtOptions(fifo_priority=a.rt_priority or None, cpus=_cpus(a.rt_cpus), lock_memory=a.lock_memory,
                         warn=False),
            loop_hook=TickTimer,
        )
        # franky-sim stands for the robot but shares our CPUs: on a busy machine it can stall for
        # longer than a real Franka ever would, and the loop's heartbeat (written after each
        # readOnce) stalls with it; the parent's hang verdict waits 5 s here instead of 0.5 s
        rp = RtProcess(spec, tactile=tactile, child_timeout=5.0)
        closers.append(rp.close)
        frames_sent = [0]
        counting = threading.Event()
        if loaded:
            from lapwrench.hardware.detector_process import DetectorProcess, shipped_factory, spec_factory
            from lapwrench.perception.synthetic import draw_instrument_scene

            factory = (
                functools.partial(shipped_factory, (640, 480), 1, a.detector == "onnx-flip")
                if a.detector.startswith("onnx")
                else functools.partial(spec_factory, "classical", (640, 480))
            )
            det = DetectorProcess(factory, rp.bus_name, (640, 480), cpus=_cpus(a.detector_cpus) or others).start()
            closers.append(det.stop)
            rp.detector_pid = det.pid
            images = [draw_instrument_scene((640, 480), seed=i)[0] for i in range(8)]

            def camera() -> None:  # 25 fps synthetic laparoscope frames into the frame slot
                i = 0
                next_t = time.monotonic()
                while not stop.is_set():
                    det.publish(images[i % len(images)], time.monotonic())
                    if counting.is_set():
                        frames_sent[0] += 1
                    i += 1
                    next_t += 0.04
                    stop.wait(max(0.0, next_t - time.monotonic()))

            def busy() -> None:  # pure Python, never releases the GIL on its own
                x = 0
                while not stop.is_set():
                    x += 1

            threads += [threading.Thread(target=camera, daemon=True), threading.Thread(target=busy, daemon=True)]
        threads.append(threading.Thread(target=feed_tactile, daemon=True))
        for t in threads:
            t.start()
        ready = rp.start()
        client = None
        if live:
            from lapwrench.hardware.log import RunLogger
            from lapwrench.robot.model import RobotModel

            logger = RunLogger(None, {"bench": "loop"}, model=RobotModel("fr3"), live=("127.0.0.1", 0))
            closers.append(logger.close)
            rp.set_logger(logger)
            assert logger.live is not None
            client = LiveClient(logger.live.address[1])
            closers.append(client.close)
        fake.set_t0(time.monotonic())
        det_frames0 = det.frames_done if det is not None else 0
        t_run = time.monotonic()
        counting.set()
        res = rp.run(a.seconds)
        counting.clear()
        wall = time.monotonic() - t_run
        det_frames = (det.frames_done - det_frames0) if det is not None else 0
    finally:
        stop.set()
        for t in threads:
            t.join(2.0)
        for c in reversed(closers):
            c()
    st, rep = res.stats, res.report
    comp = st.compute_us
    tick = np.asarray(rep.get("tick_us", []), dtype=float)
    hook = np.asarray(rep.get("hook_us", []), dtype=float)
    # the loop checks each cycle's busy time: its compute plus the hooks after the previous command (the first
    # hook ran before the first cycle); the series keep the last 2^20 cycles, the supervisor's count the whole run
    prev_hook = hook[-(comp.size + 1):-1] if hook.size >= comp.size + 1 else None
    busy = comp + prev_hook if prev_hook is not None else comp
    miss = busy > a.budget_us
    fs = server.stats
    out = {
        "run": name,
        "cycles": st.cycles,
        "robot_time_s": round(st.robot_time, 3),
        "wall_time_s": round(wall, 3),
        "compute_p50_us": round(float(np.percentile(comp, 50)), 1),
        "compute_p99_us": round(float(np.percentile(comp, 99)), 1),
        "compute_max_us": round(float(comp.max()), 1),
        "compute_max_at_cycle": int(np.argmax(comp)),
        "tick_p50_us": round(float(np.percentile(tick, 50)), 1) if tick.size else None,
        "tick_p99_us": round(float(np.percentile(tick, 99)), 1) if tick.size else None,
        "tick_share_of_compute_p50_pct": round(100 * float(np.percentile(tick, 50) / np.percentile(comp, 50)), 1)
        if tick.size
        else None,
        "hooks_p50_us": round(float(np.percentile(hook, 50)), 1) if hook.size else None,
        "hooks_p99_us": round(float(np.percentile(hook, 99)), 1) if hook.size else None,
        "busy_p99_us": round(float(np.percentile(busy, 99)), 1) if prev_hook is not None else None,
        "deadline_misses": st.deadline_misses,  # the supervisor's, on busy time, whole run
        "deadline_misses_per_10s": round(st.deadline_misses * 10.0 / max(st.robot_time, 1e-9), 1),
        "compute_misses": int((comp > a.budget_us).sum()),  # compute alone over the budget (the rule before 89ec291)
        "longest_miss_run_cycles": longest_run(miss),
        "ft_fresh_pct": round(100.0 * rep["ft_fresh_cycles"] / max(1, rep["hook_cycles"]), 3),
        "ft_catch_up_cycles": rep.get("ft_catch_ups"),  # late cycles that drained the F/T again before the tick
        "cycle_p50_us": round(st.percentile("cycle", 50), 1),
        "cycle_p99_us": round(st.percentile("cycle", 99), 1),
        "detector_fps_hz": round(det_frames / wall, 1) if loaded else None,
        "frames_published_hz": round(frames_sent[0] / wall, 1) if loaded else None,
        "frankysim_step_p50_us": None if fs is None else round(fs.p50_us, 1),
        "frankysim_realtime_factor_x": None if fs is None else round(fs.realtime_factor, 3),
        "live_messages_per_s": round(client.messages / wall, 1) if client is not None else None,
        "live_kbytes_per_s": round(client.bytes / wall / 1e3, 1) if client is not None else None,
        "page_faults_major": rep.get("major_faults"),  # the loop's process, from its first cycle to its end
        "page_faults_minor": rep.get("minor_faults"),
        # the loop's thread from its first cycle to its last thousandth: faults inside the cycling (a locked
        # process counts the pages it maps as faults when it maps them), and preemptions
        "loop_page_faults_minor_in_cycles": rep.get("faults_in_cycles", (None, None))[0],
        "loop_page_faults_major_in_cycles": rep.get("faults_in_cycles", (None, None))[1],
        "loop_involuntary_switches_in_cycles": rep.get("involuntary_switches_in_cycles"),
        **phases(comp, tick, hook, np.asarray(rep.get("cycle_stamps", np.zeros((0, 4)))), a.budget_us,
                 FT_CATCH_UP_S * 1e6),
        "rt_problems": ready.get("rt_problems"),
        "alarm": st.alarm,
        "stopped_at_rest": st.stopped_at_rest,
    }
    return out


def _pin(pid: int | None, cpus: tuple[int, ...]) -> None:
    """Every thread of process ``pid`` onto ``cpus``."""
    for tid in os.listdir(f"/proc/{pid}/task"):
        with contextlib.suppress(ProcessLookupError):  # a thread that ended meanwhile
            os.sched_setaffinity(int(tid), cpus)


def _cpus(text: str | None) -> tuple[int, ...] | None:
    return None if not text else tuple(int(c) for c in text.split(","))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=10.0, help="robot seconds per run (>= 10 for the report)")
    ap.add_argument("--budget-us", type=float, default=800.0, help="compute-time budget per cycle (us)")
    ap.add_argument("--runs", default="idle,loaded,live", help="which runs, comma-separated: idle, loaded, live")
    ap.add_argument(
        "--detector",
        choices=["onnx", "onnx-flip", "classical"],
        default="onnx",
        help="loaded run: the shipped ONNX model single pass (onnx), with its mirrored second pass (onnx-flip),"
        " or the classical detector",
    )
    ap.add_argument(
        "--ft-box-priority", type=int, default=70, help="SCHED_FIFO priority of the simulated F/T box (0: off)"
    )
    ap.add_argument("--rt-priority", type=int, default=80, help="SCHED_FIFO priority of the loop (0: off)")
    ap.add_argument("--rt-cpus", default=None, help="pin the loop's process to these CPUs")
    ap.add_argument("--detector-cpus", default=None, help="pin the detector process to these CPUs")
    ap.add_argument("--others-cpus", default=None,
                    help="pin franky-sim, the F/T box, this process and (unless --detector-cpus) the detector to these"
                    " CPUs (with --rt-cpus: the loop's CPU left to the loop)")
    ap.add_argument("--frankysim-nice", type=int, default=0,
                    help="nice value of franky-sim's threads (e.g. -10: a real Franka has a computer of its own)")
    ap.add_argument("--lock-memory", action=argparse.BooleanOptionalAction, default=True,
                    help="lock the loop's memory (mlockall, RtOptions.lock_memory)")
    a = ap.parse_args()

    from lapwrench.hardware.frankysim import frankysim_available

    missing = frankysim_available()
    if missing:
        print(f"bench/loop.py: franky-sim/pylibfranka unavailable: {missing}", file=sys.stderr)
        return 2
    runs = {}
    for name in a.runs.split(","):
        r = one_run(name, a, loaded=name == "loaded", live=name == "live")
        runs[name] = r
        print(
            f"{name:>6}: {r['cycles']} cycles, robot {r['robot_time_s']} s in {r['wall_time_s']} s wall;"
            f" compute p50 {r['compute_p50_us']} us p99 {r['compute_p99_us']} us (tick p50 {r['tick_p50_us']} /"
            f" p99 {r['tick_p99_us']} us, {r['tick_share_of_compute_p50_pct']} % of compute); after the command,"
            f" hooks p50 {r['hooks_p50_us']} / p99 {r['hooks_p99_us']} us, busy p99 {r['busy_p99_us']} us;"
            f" misses {r['deadline_misses']} (busy > {a.budget_us:.0f} us; compute alone {r['compute_misses']}),"
            f" longest run {r['longest_miss_run_cycles']};"
            f" F/T fresh {r['ft_fresh_pct']} %; detector {r['detector_fps_hz']} fps;"
            f" franky-sim step p50 {r['frankysim_step_p50_us']} us, x{r['frankysim_realtime_factor_x']};"
            f" page faults in the loop's process {r['page_faults_major']} major / {r['page_faults_minor']} minor"
            f" ({r['loop_page_faults_minor_in_cycles']} minor inside the cycling),"
            f" involuntary switches {r['loop_involuntary_switches_in_cycles']};"
            f" read wait p50 {r.get('read_wait_p50_us')} us, command p50 {r.get('command_p50_us')} us, tail after it"
            f" p50 {r.get('tail_p50_us')} / p99 {r.get('tail_p99_us')} us; misses led by {r.get('misses_led_by')},"
            f" {r.get('misses_after_a_late_state')} after a late state;"
            f" rt: {r['rt_problems'] or 'SCHED_FIFO ' + str(a.rt_priority) if a.rt_priority else 'normal priority'}"
        )
    res: dict[str, Any] = {"deadline_budget_us": a.budget_us, "detector": a.detector, "rt_priority": a.rt_priority}
    for name, r in runs.items():
        for k, v in r.items():
            if k not in ("run", "rt_problems"):
                res[f"{name}_{k}"] = v
    res["rt_problems"] = next((r["rt_problems"] for r in runs.values() if r["rt_problems"]), [])
    print(json.dumps(res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
