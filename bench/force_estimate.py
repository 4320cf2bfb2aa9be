"""Error of the simulated robot's external-force estimate while the scope pivots at 0.5, 1 and 2 rad/s.

The arm swings the scope about the incision point on a cone (tilt 0.35 rad about the start axis,
no roll), at a constant pivot angular speed after a 1 s smooth ramp-in; joint references come from
a closed-loop inverse kinematics of that pose with a null-space pull toward the start posture.
Two estimators read the same run with the joint-torque noise and bias of the simulated closed loop:
``tick_mean`` (the joint torque averaged over each 1 ms tick, the default) and ``tick_end`` (the
former model: sampled at the end of the tick, on the servo's per-tick torque sawtooth).

The error is the estimate minus the true external force on the end effector (the simulator's
trocar contact force; no hand). "Lateral" is its part orthogonal to the shaft, the part that
drives the adaptive RCM point (eq 23-24). Figures are over the steady part of each run.

Usage: python bench/force_estimate.py [--seconds 2] [--speeds 0.5 1 2]
The last line printed is one JSON object with unit-suffixed keys.
"""

from __future__ import annotations

import argparse
import json

import numpy as np
import pinocchio as pin

from lapwrench.robot.model import RobotModel
from lapwrench.sim.loop import TORQUE_BIAS, TORQUE_NOISE
from lapwrench.sim.robot import ForceEstimateConfig, SimRobot
from lapwrench.sim.scene.arm import TAU_MAX
from lapwrench.sim.world import CONTROL_DT, SimWorld

TILT = 0.35  # rad, half-angle of the cone the shaft sweeps
RAMP = 1.0  # s, smooth ramp-in of the tilt and of the speed
SAMPLINGS = ("tick_mean", "tick_end")


def _smoothstep(x: float) -> float:
    x = min(1.0, max(0.0, x))
    return x * x * (3.0 - 2.0 * x)


class ConePivot:
    """Joint references that pivot the scope about ``p_R`` on a cone at pivot angular speed ``omega``."""

    def __init__(self, model: RobotModel, q0: np.ndarray, p_R: np.ndarray, omega: float) -> None:
        self.model = model
        self.q0 = q0.copy()
        self.q = q0.copy()
        self.p_R = p_R
        kin = model.kinematics(q0, np.zeros(7))
        self.d0 = kin.d_z.copy()
        self.depth = float(self.d0 @ (p_R - kin.p_E))  # flange to p_R along the shaft
        e1 = np.cross(self.d0, [1.0, 0.0, 0.0])
        self.e1 = e1 / np.linalg.norm(e1)
        self.e2 = np.cross(self.d0, self.e1)
        self.R = kin.R_E.copy()
        self.d = self.d0.copy()
        self.rate = omega / np.sin(TILT)  # rad/s about the cone axis
        self.phase = 0.0

    def step(self, t: float) -> np.ndarray:
        """The joint reference at time ``t`` (called once per tick, in order)."""
        s = _smoothstep(t / RAMP)
        self.phase += self.rate * s * CONTROL_DT
        tilt = TILT * s
        d = np.cos(tilt) * self.d0 + np.sin(tilt) * (np.cos(self.phase) * self.e1 + np.sin(self.phase) * self.e2)
        axis = np.cross(self.d, d)
        sin_a = np.linalg.norm(axis)
        if sin_a > 1e-12:  # the smallest rotation taking the old shaft axis to the new one: no roll
            self.R = pin.exp3(axis / sin_a * np.arcsin(min(1.0, sin_a))) @ self.R
        self.d = d
        p_E = self.p_R - self.depth * d
        for _ in range(3):  # closed-loop IK, null-space pull to the start posture
            kin = self.model.kinematics(self.q, np.zeros(7))
            J_pinv = np.linalg.pinv(kin.J_E)
            err = np.concatenate([pin.log3(self.R @ kin.R_E.T), p_E - kin.p_E])
            self.q = self.q + J_pinv @ err + (np.eye(7) - J_pinv @ kin.J_E) @ (0.002 * (self.q0 - self.q))
        return self.q.copy()


def run(omega: float, seconds: float) -> dict[str, dict[str, float]]:
    """Pivot at ``omega`` rad/s for ``seconds`` after the ramp-in; error figures per sampling."""
    world = SimWorld()
    model = RobotModel(world.scene.config.kind, world.scene.config.scope)
    noise = {"torque_noise": TORQUE_NOISE, "torque_bias": TORQUE_BIAS, "seed": 1}
    robots = {s: SimRobot(world, estimate=ForceEstimateConfig(sampling=s, **noise)) for s in SAMPLINGS}
    for r in robots.values():
        r.connect()
    pivot = ConePivot(model, world.scene.q0, world.incision_position(), omega)
    lateral: dict[str, list[float]] = {s: [] for s in SAMPLINGS}
    total: dict[str, list[float]] = {s: [] for s in SAMPLINGS}
    speed, truth_norm, saturated = [], [], 0
    n = round((RAMP + seconds) / CONTROL_DT)
    for k in range(n):
        t = (k + 1) * CONTROL_DT
        robots["tick_mean"].command(pivot.step(t))  # steps the shared world once
        saturated += int(np.any(np.abs(world.motor_torque()) >= TAU_MAX - 1e-9))
        if t <= RAMP:
            for r in robots.values():
                r.read()
            continue
        truth = world.contact_force() + world.hand_force()
        kin = model.kinematics(world.q, world.dq)
        speed.append(float(np.linalg.norm(kin.P @ kin.twist_E[:3])))
        truth_norm.append(float(np.linalg.norm(truth)))
        for s, r in robots.items():
            err = r.read().external_force - truth
            lateral[s].append(float(np.linalg.norm(kin.P @ err)))
            total[s].append(float(np.linalg.norm(err)))
    out: dict[str, dict[str, float]] = {}
    for s in SAMPLINGS:
        out[s] = {
            "lateral_p95": float(np.percentile(lateral[s], 95)),
            "lateral_max": float(np.max(lateral[s])),
            "total_p95": float(np.percentile(total[s], 95)),
        }
    out["run"] = {
        "speed_mean": float(np.mean(speed)),
        "speed_min": float(np.min(speed)),
        "speed_max": float(np.max(speed)),
        "truth_max": float(np.max(truth_norm)),
        "saturated_ticks": float(saturated),
        "rcm_error_max_mm": float(world.rcm_error() * 1e3),
    }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=2.0, help="steady pivoting seconds per speed")
    ap.add_argument("--speeds", type=float, nargs="+", default=[0.5, 1.0, 2.0], help="pivot speeds (rad/s)")
    args = ap.parse_args()

    summary: dict[str, float] = {}
    print("pivot   achieved        |F_true|  lateral error p95 / max (N)        total p95 (N)")
    print("rad/s   rad/s           max N     tick_mean        tick_end (old)    new     old")
    for omega in args.speeds:
        res = run(omega, args.seconds)
        new, old, info = res["tick_mean"], res["tick_end"], res["run"]
        print(
            f"{omega:<7.2f} {info['speed_min']:.2f}-{info['speed_max']:.2f}     {info['truth_max']:<8.2f}  "
            f"{new['lateral_p95']:5.2f} / {new['lateral_max']:5.2f}    "
            f"{old['lateral_p95']:6.2f} / {old['lateral_max']:6.2f}"
            f"     {new['total_p95']:5.2f}   {old['total_p95']:6.2f}"
        )
        if info["saturated_ticks"]:
            print(f"        warning: a joint servo saturated on {info['saturated_ticks']:.0f} ticks")
        tag = f"at_{omega:g}_rad_s"
        summary[f"err_lateral_p95_n_{tag}"] = round(new["lateral_p95"], 3)
        summary[f"err_lateral_max_n_{tag}"] = round(new["lateral_max"], 3)
        summary[f"err_total_p95_n_{tag}"] = round(new["total_p95"], 3)
        summary[f"old_err_lateral_p95_n_{tag}"] = round(old["lateral_p95"], 3)
        summary[f"old_err_lateral_max_n_{tag}"] = round(old["lateral_max"], 3)
        summary[f"pivot_speed_mean_rad_s_{tag}"] = round(info["speed_mean"], 3)
    print(json.dumps(summary))


if __name__ == "__main__":
    main()
