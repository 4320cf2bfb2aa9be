"""Real-time factor of the simulation at 1 kHz control, with and without 25 fps laparoscope rendering.

Three levels, each run with and without rendering the 640x480 laparoscope view at 25 fps:

- physics: ``SimWorld.step`` with scripted joint references (precomputed outside the timed loop), a
  hand wrench on and an instrument moved every tick, as in ``bench/sim.py`` before;
- sim side: everything the closed loop asks of the simulation in one control period, without the
  controller: ``SimRobot.read`` (joint state and the external force estimate), the F/T sensor, the
  tactile array, the camera, ``SimRobot.command`` (the physics);
- closed loop: ``ClosedLoop.step``, i.e. the sim side plus the controller tick and the supervisor,
  as in the demo (instrument points projected from the geometry, so no detector inference; every
  rendered frame handed to a callback, as the demo's video takes it); with rendering also a third
  way, ``ClosedLoop(render_in_background=True)``: the same frames drawn in a child process while the
  loop steps on (``closed_loop_render_25fps_background_realtime_x``).

Same-run reference: MuJoCo's ``mj_step`` alone on the same scene (a copy of the world's state); a
control period makes ``substeps_per_tick`` of them, so ``sim_side_over_mj_steps_x`` is the whole
simulation side of a period in units of its bare physics steps. All configurations run in
interleaved chunks, so a change of machine load hits them alike.

Usage: MUJOCO_GL=egl python bench/sim.py [--seconds 5] [--kind panda] [--chunks 10]
The last line printed is one JSON object with unit-suffixed keys.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from collections.abc import Callable

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco
import numpy as np

from lapwrench.robot_kinds import ROBOT_KINDS
from lapwrench.sim.scene.build import build_scene
from lapwrench.sim.scene.config import SceneConfig
from lapwrench.sim.world import CONTROL_DT, SimWorld

FPS = 25.0
AMP = np.array([0.01, 0.01, 0.01, 0.015, 0.03, 0.02, 0.2])  # rad, scripted reference amplitude


def _references(q0: np.ndarray, first: int, n: int) -> np.ndarray:
    """Scripted joint references of ticks ``first`` .. ``first + n - 1`` (0.4 Hz sinusoids), one row each."""
    t = np.arange(first, first + n)[:, None] * CONTROL_DT
    return q0 + AMP * np.sin(2 * np.pi * 0.4 * t)


class Physics:
    """SimWorld.step with scripted references; optional world.render() at 25 fps."""

    def __init__(self, kind: str, render: bool) -> None:
        self.world = SimWorld(build_scene(SceneConfig(kind=kind)))
        self.world.render()  # create the GL context outside the timed loop
        self.render = render
        self.world.set_hand_wrench(force=[2.0, -1.0, 0.0], torque=[0.0, 0.0, 0.05])
        self.i = 0
        self.frames = 0
        self.step_times: list[float] = []
        self._every = round(1.0 / (FPS * CONTROL_DT))

    def run(self, n: int) -> float:
        w, times = self.world, self.step_times
        refs = _references(w.scene.q0, self.i + 1, n)  # scripted, computed outside the timed loop
        t_start = time.perf_counter()
        for k in range(n):
            i = self.i = self.i + 1
            t = i * CONTROL_DT
            w.set_instrument_tip(0, w.port_position(0) + np.array([-0.02, -0.07 + 0.01 * np.sin(t), -0.12]))
            t0 = time.perf_counter()
            w.step(refs[k])
            times.append(time.perf_counter() - t0)
            if self.render and i % self._every == 0:
                w.render()
                self.frames += 1
        return time.perf_counter() - t_start

    def close(self) -> None:
        self.world.close()


class SimSide:
    """One control period of the simulation as ClosedLoop drives it, with scripted references."""

    def __init__(self, kind: str, render: bool) -> None:
        from lapwrench.sim.camera import SimCamera
        from lapwrench.sim.loop import TORQUE_BIAS, TORQUE_NOISE
        from lapwrench.sim.robot import ForceEstimateConfig, SimRobot
        from lapwrench.sim.sensors import SimForceTorqueSensor, TactileGripModel

        self.world = w = SimWorld(build_scene(SceneConfig(kind=kind)))
        w.set_instrument_tip(0, w.incision_rest_position() + np.array([0.01, 0.0, -0.145]))
        self.robot = SimRobot(w, estimate=ForceEstimateConfig(torque_noise=TORQUE_NOISE, torque_bias=TORQUE_BIAS))
        self.ft = SimForceTorqueSensor(w, seed=1)
        self.tactile = TactileGripModel(seed=2)
        self.camera = SimCamera(w, fps=FPS) if render else None
        if render:
            w.render()
        self.ft.tare()
        self.q0 = self.robot.connect().q
        self.i = 0

    def run(self, n: int) -> float:
        robot, ft, tactile, camera, w = self.robot, self.ft, self.tactile, self.camera, self.world
        refs = _references(self.q0, self.i, n)
        t_start = time.perf_counter()
        for k in range(n):
            t = self.i * CONTROL_DT
            self.i += 1
            w.set_hand_wrench(force=np.array([1.0 * np.sin(t), 0.5, 0.0]))
            if camera is not None:
                camera.capture(t)
            robot.read()
            ft.read(t)
            tactile.read(t, 30.0)
            robot.command(refs[k])
        return time.perf_counter() - t_start

    def close(self) -> None:
        self.world.close()


class Closed:
    """The demo's closed loop (hand on the handle, instrument points projected from the geometry); with
    rendering, every frame goes to a callback as the demo's video takes it, drawn in the loop's process
    or (``background``) in a child process while the loop steps on."""

    def __init__(self, kind: str, render: bool, background: bool = False) -> None:
        from lapwrench.config import load
        from lapwrench.sim.loop import ClosedLoop

        cfg = load("swapped-damping").replace(robot={"kind": kind})
        self.frames = 0
        self.loop = ClosedLoop(cfg, seed=0, detector="projected" if render else None,
                               on_frame=self._take if render else None, render_in_background=background)
        w = self.loop.world
        w.set_instrument_tip(0, w.incision_rest_position() + np.array([0.01, 0.0, -0.145]))
        if render:
            w.render()
        self.i = 0

    def run(self, n: int) -> float:
        loop = self.loop
        t_start = time.perf_counter()
        for _ in range(n):
            loop.world.set_hand_wrench(force=np.array([1.0 * np.sin(self.i * 1e-3), 0.5, 0.0]))
            self.i += 1
            loop.step(30.0)
        return time.perf_counter() - t_start

    def _take(self, frame: np.ndarray, t: float, mode: str) -> None:
        self.frames += 1

    def close(self) -> None:
        self.loop.close()


class MjStep:
    """mujoco.mj_step alone on a copy of a world's state (the servo holds the arm)."""

    def __init__(self, kind: str) -> None:
        w = SimWorld(build_scene(SceneConfig(kind=kind)))
        for _ in range(50):
            w.step(w.scene.q0)
        self.model, self.data = w.model, w.data
        self.n_substeps = w.n_substeps
        self.calls = 0

    def run(self, n: int) -> float:
        """Wall time of the mj_step calls of ``n`` control periods."""
        m, d, k = self.model, self.data, n * self.n_substeps
        t_start = time.perf_counter()
        for _ in range(k):
            mujoco.mj_step(m, d)
        self.calls += k
        return time.perf_counter() - t_start

    def close(self) -> None:
        pass


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=5.0, help="simulated seconds per configuration")
    ap.add_argument("--kind", choices=ROBOT_KINDS, default="panda")
    ap.add_argument("--chunks", type=int, default=10, help="interleaved chunks per configuration")
    args = ap.parse_args()

    makers: dict[str, Callable[[], object]] = {
        "mj_step": lambda: MjStep(args.kind),
        "physics": lambda: Physics(args.kind, False),
        "physics_render": lambda: Physics(args.kind, True),
        "sim_side": lambda: SimSide(args.kind, False),
        "sim_side_render": lambda: SimSide(args.kind, True),
        "closed_loop": lambda: Closed(args.kind, False),
        "closed_loop_render": lambda: Closed(args.kind, True),
        "closed_loop_render_bg": lambda: Closed(args.kind, True, background=True),
    }
    runs = {name: make() for name, make in makers.items()}
    for r in runs.values():
        r.run(200)  # warm-up: compiled kernels, caches, first frames
    phys = runs["physics"]
    assert isinstance(phys, Physics)
    phys.step_times.clear()
    render_phys = runs["physics_render"]
    assert isinstance(render_phys, Physics)
    render_phys.frames = 0

    n_total = round(args.seconds / CONTROL_DT)
    per_chunk = [n_total // args.chunks + (1 if c < n_total % args.chunks else 0) for c in range(args.chunks)]
    wall = dict.fromkeys(runs, 0.0)
    for n in per_chunk:
        for name, r in runs.items():
            wall[name] += r.run(n)  # type: ignore[attr-defined]
    for r in runs.values():
        r.close()  # type: ignore[attr-defined]

    sim_s = n_total * CONTROL_DT
    n_sub = runs["mj_step"].n_substeps  # type: ignore[attr-defined]
    mj_step_us = wall["mj_step"] / (n_total * n_sub) * 1e6
    period_us = {k: wall[k] / n_total * 1e6 for k in wall if k != "mj_step"}
    rtf = {k: sim_s / wall[k] for k in period_us}
    render_ms = (wall["physics_render"] - wall["physics"]) / max(render_phys.frames, 1) * 1e3
    bare_us = n_sub * mj_step_us

    print(f"{sim_s:.1f} s simulated per configuration, {args.chunks} interleaved chunks, robot {args.kind}")
    print(f"mj_step alone: {mj_step_us:.1f} us; {n_sub} per 1 ms control period = {bare_us:.1f} us of bare physics")
    labels = {
        "physics": "physics alone (SimWorld.step)",
        "sim_side": "sim side (robot read/command, sensors, physics)",
        "closed_loop": "closed loop (sim side + controller + supervisor)",
    }
    rows = [(k + suffix, label, how) for k, label in labels.items()
            for suffix, how in (("", "no rendering   "), ("_render", "25 fps rendering"))]
    rows.append(("closed_loop_render_bg", labels["closed_loop"], "25 fps rendered in a child process"))
    for key, label, how in rows:
        print(
            f"{label:50s} {how}: {period_us[key]:7.1f} us per period = {period_us[key] / bare_us:5.2f} x bare "
            f"mj_steps -> real-time factor {rtf[key]:5.2f}x"
        )
    print(f"rendering: {render_ms:.1f} ms per 640x480 frame ({render_phys.frames} frames)")
    steps = np.array(phys.step_times)
    result = {
        "robot": args.kind,
        "sim_seconds_s": sim_s,
        "physics_dt_ms": runs["physics"].world.timestep * 1e3,  # type: ignore[attr-defined]
        "substeps_per_tick": n_sub,
        "mj_step_us": round(mj_step_us, 2),
        "bare_mj_steps_per_period_us": round(bare_us, 2),
        "physics_per_period_us": round(period_us["physics"], 1),
        "sim_side_per_period_us": round(period_us["sim_side"], 1),
        "closed_loop_per_period_us": round(period_us["closed_loop"], 1),
        "physics_over_mj_steps_x": round(period_us["physics"] / bare_us, 2),
        "sim_side_over_mj_steps_x": round(period_us["sim_side"] / bare_us, 2),
        "closed_loop_over_mj_steps_x": round(period_us["closed_loop"] / bare_us, 2),
        "physics_realtime_x": round(rtf["physics"], 2),
        "physics_render_25fps_realtime_x": round(rtf["physics_render"], 2),
        "sim_side_realtime_x": round(rtf["sim_side"], 2),
        "sim_side_render_25fps_realtime_x": round(rtf["sim_side_render"], 2),
        "closed_loop_realtime_x": round(rtf["closed_loop"], 2),
        "closed_loop_render_25fps_realtime_x": round(rtf["closed_loop_render"], 2),
        "closed_loop_render_25fps_background_realtime_x": round(rtf["closed_loop_render_bg"], 2),
        "world_step_p50_us": round(float(np.percentile(steps, 50)) * 1e6, 1),
        "world_step_p99_us": round(float(np.percentile(steps, 99)) * 1e6, 1),
        "render_ms_per_frame": round(render_ms, 2),
    }
    print(json.dumps(result))


if __name__ == "__main__":
    main()
