"""The scope's envelope (motion/envelope.py): each wall holds on the virtual dynamics, softly."""

from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from lapwrench.config import Config, load
from lapwrench.controller import Controller
from lapwrench.motion.envelope import APPROACH_TIME, rate_row_bounds, roll_angle, wall_speed
from lapwrench.robot.limits import limit_usage
from lapwrench.virtual import DEFAULT_Q0, HandScript, VirtualLog, run_virtual

CFG = load().replace(viscous={"k_t": 2.0, "k_f": 20.0})  # light damping: the hand reaches every wall fast
ENV = CFG.envelope


def _rates(ctrl: Controller, log: VirtualLog) -> dict[str, np.ndarray]:
    """Depth (m), insertion speed (m/s), pivot speed (rad/s), roll (rad) and roll speed of each tick."""
    out: dict[str, list[float]] = {k: [] for k in ("depth", "insertion", "pivot", "roll", "roll_speed")}
    R0 = ctrl.model.kinematics(DEFAULT_Q0, np.zeros(7)).R_E
    for r in log.results:
        kin = ctrl.model.kinematics(r.q_ref, r.dq_ref)
        w, v = kin.J_E[:3] @ r.dq_ref, kin.J_E[3:] @ r.dq_ref
        out["depth"].append(CFG.scope.length - float(kin.d_z @ (r.p_R - kin.p_E)))
        out["insertion"].append(float(kin.d_z @ v))
        out["pivot"].append(float(np.linalg.norm(kin.P @ w)))
        out["roll"].append(roll_angle(kin.R_E, R0))
        out["roll_speed"].append(float(kin.d_z @ w))
    return {k: np.array(v) for k, v in out.items()}


def _run(
    force: np.ndarray, torque: np.ndarray | None = None, duration: float = 2.5, cfg: Config = CFG
) -> tuple[Controller, VirtualLog, dict[str, np.ndarray]]:
    tau = np.zeros(3) if torque is None else torque
    hand = HandScript(force=lambda t: force, torque=lambda t: tau, delta=lambda t: 2.0)
    ctrl, log = run_virtual(cfg, duration, hand=hand)
    q = np.array([r.q_ref for r in log.results])
    usage = limit_usage(q, CFG.robot.dt, ctrl.model.limits, DEFAULT_Q0)
    assert max(usage["velocity"], usage["acceleration"], usage["jerk"]) <= 1.0 and usage["position_excess"] == 0
    assert max(r.rcm_error for r in log.results) < 5e-4
    return ctrl, log, _rates(ctrl, log)


@pytest.mark.parametrize(("sign", "wall"), [(1.0, "depth_max"), (-1.0, "depth_min")])
def test_an_axial_push_stops_softly_at_the_depth_wall(sign: float, wall: str) -> None:
    _, log, r = _run(np.array([0.0, 0.0, 30.0 * sign]))
    assert ENV.depth_min - 1e-4 <= r["depth"].min() and r["depth"].max() <= ENV.depth_max + 1e-4
    target = ENV.depth_max if sign > 0 else ENV.depth_min
    assert abs(r["depth"][-1] - target) < 1e-3  # the hand holds the scope at the wall
    depth_rate = np.diff(r["depth"]) / CFG.robot.dt
    assert np.abs(depth_rate).max() <= ENV.insertion_speed_max * 1.01
    assert any(wall in res.limits_active for res in log.results)
    # soft: the scope's deceleration at the wall stays near the configured one
    acc = np.abs(np.diff(depth_rate)) / CFG.robot.dt
    near = np.abs(r["depth"][2:] - target) < 0.005
    assert near.any() and acc[near].max() < 1.5 * ENV.insertion_deceleration


def test_a_lateral_push_is_held_to_the_pivot_speed() -> None:
    _, log, r = _run(np.array([30.0, 0.0, 0.0]), duration=1.0)
    assert r["pivot"].max() <= ENV.pivot_speed_max * 1.02
    assert r["pivot"].max() >= 0.9 * ENV.pivot_speed_max  # it did reach the wall
    assert any("pivot_speed" in res.limits_active for res in log.results)


def test_a_torque_about_the_shaft_stops_at_the_roll_range_and_speed() -> None:
    cfg_roll = 0.6
    cfg = CFG.replace(envelope={"roll_range": cfg_roll, "roll_speed_max": 0.8})
    _, _, r = _run(np.zeros(3), torque=np.array([0.0, 0.0, 1.0]), duration=3.0, cfg=cfg)
    assert np.abs(r["roll_speed"]).max() <= 0.8 * 1.01
    assert np.abs(r["roll"]).max() <= cfg_roll + 1e-3
    assert abs(abs(r["roll"][-1]) - cfg_roll) < 0.01


def test_the_roll_wall_at_the_largest_range_allowed_holds() -> None:
    """Near +-pi the roll angle wraps: a wall at pi let the scope's 2 mrad overshoot wrap past it, and a twist of
    1 N m turned the scope on to 4.0 rad (the config refuses a range beyond 3.1 rad since). At 3.1 the wall holds,
    measured unwrapped (the joints let the roll go past pi this way)."""
    cfg = CFG.replace(envelope={"roll_range": 3.1, "roll_speed_max": 1.5})
    hand = HandScript(force=lambda t: np.zeros(3), torque=lambda t: np.array([0.0, 0.0, 1.0]), delta=lambda t: 2.0)
    ctrl, log = run_virtual(cfg, 5.0, hand=hand)
    roll = np.unwrap(_rates(ctrl, log)["roll"])
    assert 3.09 < roll.max() <= 3.1 + 0.005 and abs(roll[-1] - 3.1) < 0.005


def test_roll_angle_is_the_twist_about_the_shaft_only() -> None:
    R0 = pin.rpy.rpyToMatrix(0.3, -0.2, 0.5)
    d0 = R0[:, 2]
    twist = pin.exp3(0.4 * d0) @ R0
    assert roll_angle(twist, R0) == pytest.approx(0.4)
    swing_axis = np.cross(d0, [1.0, 0.0, 0.0])
    swing = pin.exp3(0.5 * swing_axis / np.linalg.norm(swing_axis)) @ R0
    assert roll_angle(swing, R0) == pytest.approx(0.0, abs=1e-12)



@pytest.mark.parametrize("eps", [0.0, 1e-13, 1e-7])
def test_roll_angle_is_defined_with_the_shaft_turned_a_half_turn(eps: float) -> None:
    """No shortest rotation exists from d_0 to -d_0 (within round-off; the compiled tick raised
    ZeroDivisionError, NaN without the JIT): the half turn about the start x axis is taken,
    then a twist of 0.3 rad about the shaft reads as 0.3."""
    R0 = pin.rpy.rpyToMatrix(0.3, -0.2, 0.5)
    x0, d0 = R0[:, 0], R0[:, 2]
    tilt = np.cross(d0, x0)  # a swing of eps off the exact half turn, about the start y axis
    flipped = pin.exp3(eps * tilt) @ pin.exp3(np.pi * x0) @ R0
    d = flipped[:, 2]
    assert 1.0 + d0 @ d < 1e-6
    assert roll_angle(flipped, R0) == pytest.approx(0.0, abs=1e-3)
    assert roll_angle(pin.exp3(0.3 * d) @ flipped, R0) == pytest.approx(0.3, abs=1e-3)


def test_wall_speed_and_rate_bounds() -> None:
    assert wall_speed(0.02, 0.5, 1.0) == pytest.approx(np.sqrt(2 * 0.5 * 0.02))
    assert wall_speed(0.02, 0.5, 0.05) == 0.05  # capped by the speed limit
    assert wall_speed(-0.02, 0.5, 1.0) < 0.0  # beyond the wall: led back
    lo, hi = rate_row_bounds(0.0, -1.0, 1.0, 2.0, 1e-3)
    assert (lo, hi) == (-1.0 / APPROACH_TIME, 1.0 / APPROACH_TIME)
    lo, hi = rate_row_bounds(3.0, -1.0, 1.0, 2.0, 1e-3)  # far too fast: brought back at 2 (units/s²)
    assert hi == -2.0 and lo <= hi
