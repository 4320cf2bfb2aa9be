"""Real-time factor of the simulation at 1 kHz control, with and without 25 fps laparoscope rendering.

Two figures each: the physics alone (SimWorld.step with scripted references) and the whole closed
loop (simulated sensors, the controller tick, the supervisor and the physics, as in the demo).

Usage: MUJOCO_GL=egl python bench/sim.py [--seconds 5] [--kind panda]
The last line printed is one JSON object with unit-suffixed keys.
"""

from __future__ import annotations

import argparse
import json
import os
import time

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np

from lapwrench.sim.scene import SceneConfig, build_scene
from lapwrench.sim.world import CONTROL_DT, SimWorld


def _run(world: SimWorld, seconds: float, render_fps: float | None) -> tuple[float, np.ndarray, int]:
    """Wall time, per-step times (s) and frame count for ``seconds`` of simulated time."""
    world.reset()
    q0 = world.scene.q0
    amp = np.array([0.01, 0.01, 0.01, 0.015, 0.03, 0.02, 0.2])
    n = round(seconds / CONTROL_DT)
    every = round(1.0 / (render_fps * CONTROL_DT)) if render_fps else 0
    step_times = np.empty(n)
    frames = 0
    world.set_hand_wrench(np.array([2.0, -1.0, 0.0, 0.0, 0.0, 0.05]))
    t_start = time.perf_counter()
    for i in range(n):
        t = (i + 1) * CONTROL_DT
        q_ref = q0 + amp * np.sin(2 * np.pi * 0.4 * t)
        world.set_instrument_tip(0, world.port_position(0) + np.array([-0.02, -0.07 + 0.01 * np.sin(t), -0.12]))
        t0 = time.perf_counter()
        world.step(q_ref)
        step_times[i] = time.perf_counter() - t0
        if every and i % every == 0:
            world.render()
            frames += 1
    return time.perf_counter() - t_start, step_times, frames


def _closed_loop(seconds: float, kind: str, render: bool) -> float:
    """Wall time of ``seconds`` of the demo's closed loop (hand on the handle, instrument tracked from
    the projected geometry, so the figure is rendering + control, not detector inference)."""
    from lapwrench.config import load
    from lapwrench.sim.loop import ClosedLoop

    cfg = load("swapped-damping").replace(robot={"kind": kind})
    loop = ClosedLoop(cfg, seed=0, detector="projected" if render else None)
    loop.world.set_instrument_tip(0, loop.world.incision_rest_position() + np.array([0.01, 0.0, -0.145]))
    if render:
        loop.world.render()
    n = round(seconds / CONTROL_DT)
    t_start = time.perf_counter()
    for i in range(n):
        loop.world.set_hand_wrench(np.array([1.0 * np.sin(i * 1e-3), 0.5, 0.0, 0.0, 0.0, 0.0]))
        loop.step(30.0)
    wall = time.perf_counter() - t_start
    loop.world.close()
    return wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0, help="simulated seconds per run")
    ap.add_argument("--kind", choices=("panda", "fr3"), default="panda")
    args = ap.parse_args()

    world = SimWorld(build_scene(SceneConfig(kind=args.kind)))
    world.render()  # create the GL context outside the timed loop
    wall_a, steps, _ = _run(world, args.seconds, None)
    rtf_a = args.seconds / wall_a
    print(f"no rendering      : {args.seconds:.1f} s simulated in {wall_a:.2f} s -> real-time factor {rtf_a:.1f}x")
    wall_b, _, frames = _run(world, args.seconds, 25.0)
    rtf_b = args.seconds / wall_b
    print(
        f"25 fps rendering  : {args.seconds:.1f} s simulated in {wall_b:.2f} s ({frames} frames 640x480) "
        f"-> real-time factor {rtf_b:.1f}x"
    )
    render_ms = (wall_b - wall_a) / max(frames, 1) * 1e3
    world.close()
    wall_c = _closed_loop(args.seconds, args.kind, render=False)
    wall_d = _closed_loop(args.seconds, args.kind, render=True)
    rtf_c, rtf_d = args.seconds / wall_c, args.seconds / wall_d
    print(f"closed loop, no rendering     : real-time factor {rtf_c:.1f}x (sensors, controller, supervisor, physics)")
    print(f"closed loop, 25 fps rendering : real-time factor {rtf_d:.1f}x")
    print(f"ratio closed loop / physics alone (no rendering): {rtf_c / rtf_a:.2f}")
    result = {
        "robot": args.kind,
        "sim_seconds_s": args.seconds,
        "physics_dt_ms": world.timestep * 1e3,
        "substeps_per_tick": world.n_substeps,
        "rtf_no_render_x": round(rtf_a, 2),
        "rtf_render_25fps_x": round(rtf_b, 2),
        "step_us_p50": round(float(np.percentile(steps, 50)) * 1e6, 1),
        "step_us_p99": round(float(np.percentile(steps, 99)) * 1e6, 1),
        "render_ms_per_frame": round(render_ms, 1),
        "rtf_closed_loop_no_render_x": round(rtf_c, 2),
        "rtf_closed_loop_render_25fps_x": round(rtf_d, 2),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
