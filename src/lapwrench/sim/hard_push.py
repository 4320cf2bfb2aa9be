"""``hard-push``: a hostile hand on the handle, in the MuJoCo world with the robot in the loop (issue 9).

Runs, each from the same reset pose in a fresh :class:`~lapwrench.sim.loop.ClosedLoop`:

- lateral pushes on the handle along the flange's x and y axes at the start (kept perpendicular to
  the shaft as it turns) and axial pushes in and out along the shaft, at 10, 20 and 30 N, each at
  grip δ 2.0 and 1.1 (grip forces of 30 N and 17 N on the tactile model, as in the grip scenario);
- a speed-driven hand (:class:`~lapwrench.sim.surgeon.SpeedDrivenHand`) trying to pivot the
  scope at 0.25, 0.5 and 1.0 rad/s, at δ 2.0, with at most 30 N;
- a 1 N m torque about the shaft (roll), at δ 2.0.

The force rises over 50 ms, is held, and falls over 50 ms to end after ``PUSH_S``; the hand then
lets go (grip to zero) and the run settles for ``SETTLE_S``. A hand can neither apply nor drop
30 N within one 1 ms tick (a step would also make the measured residual ΔF spike while the
joint-torque estimate catches up). ``time_scale`` shortens the push and the settling only.

``opts.world`` scales the pushes, the hand's speed and the grip
(:meth:`~lapwrench.sim.variation.WorldVariation.hand`); a run's ``magnitude`` and ``grip_force_N``
metrics stay the case's nominal values.

A safety hold (:class:`~lapwrench.sim.loop.SafetyStopError`) ends a run and is recorded as its
alarm; so is a simulation stop (:class:`~lapwrench.sim.world.SimulationUnstableError`, e.g. the
scope leaving the trocar). Each run is checked against the issue's targets: physical RCM error
≤ 2 mm, trocar force ≤ 10 N, scope tip depth beyond the unloaded incision point inside the envelope's
[depth_min, depth_max], every joint reference inside the Franka limits.
"""

from __future__ import annotations

import math
import time
from collections import Counter
from dataclasses import dataclass
from typing import Literal, Protocol, TypedDict

import numpy as np

from lapwrench.config import Config
from lapwrench.sim.loop import ClosedLoop, SafetyStopError, Trace
from lapwrench.sim.results import Metric, Run, ScenarioOptions, ScenarioResult, number, run_metrics
from lapwrench.sim.surgeon import SpeedDrivenHand, across_shaft, axis_angle
from lapwrench.sim.variation import WorldVariation
from lapwrench.sim.world import CONTROL_DT, SimulationUnstableError, SimWorld

PUSH_S = 1.5  # s the hand pushes (full time scale)
SETTLE_S = 1.0  # s after the release (the insertion axis is lightly damped: drift shows here)
RISE_S = 0.05  # s for the hand's force to rise and to fall (physics of the hand: not scaled)
GRIP_FORCE = {2.0: 30.0, 1.1: 17.0}  # δ -> grip force (N) that gives it on the tactile model
FORCES_N = (10.0, 20.0, 30.0)
HAND_SPEEDS = (0.25, 0.5, 1.0)  # rad/s
ROLL_TORQUE = 1.0  # N m
END_RATE_S = 0.05  # s over which the tip's depth rate at the end of a run is taken
STILL_MOVING_MM_S = 1.0  # |depth rate| (mm/s) at the end of a run that counts as not settled
TARGET_RCM_MM = 2.0
TARGET_FORCE_N = 10.0

Kind = Literal["lateral", "axial", "speed", "roll"]


class _Stop(TypedDict, total=False):
    """How a run ended early (empty: it did not): a safety hold or a simulation stop."""

    kind: str
    time: float
    reason: str
    after: tuple[float, float, float, float]  # a hold's: RCM error (m), trocar force (N), tilt (deg), tip depth (m)


@dataclass(frozen=True)
class PushCase:
    """One hard-push run.

    ``axis``: direction in the flange frame lap_E at the start pose (z along the shaft, into the
    body); for ``speed`` the direction the tip should turn to. ``magnitude``: N (lateral, axial),
    rad/s (speed) or N m (roll, about the shaft).
    """

    label: str
    kind: Kind
    axis: tuple[float, float, float]
    magnitude: float
    delta: float  # nominal grip gain δ; the grip force comes from GRIP_FORCE

    @property
    def grip_force(self) -> float:
        """Grip force (N) on the tactile model."""
        return GRIP_FORCE[self.delta]


def default_cases() -> list[PushCase]:
    """The full set: 12 lateral, 12 axial, 3 speed-driven, 1 roll (28 runs)."""
    cases = []
    pushes: tuple[tuple[Kind, tuple[tuple[str, tuple[float, float, float]], ...]], ...] = (
        ("lateral", (("+x_E", (1.0, 0.0, 0.0)), ("+y_E", (0.0, 1.0, 0.0)))),
        ("axial", (("in", (0.0, 0.0, 1.0)), ("out", (0.0, 0.0, -1.0)))),
    )
    for kind, dirs in pushes:
        for name, axis in dirs:
            for force in FORCES_N:
                for delta in GRIP_FORCE:
                    cases.append(PushCase(f"{kind} {name} {force:.0f} N δ{delta}", kind, axis, force, delta))
    for speed in HAND_SPEEDS:
        cases.append(PushCase(f"hand {speed} rad/s δ2.0", "speed", (1.0, 0.0, 0.0), speed, 2.0))
    cases.append(PushCase(f"roll {ROLL_TORQUE} N m δ2.0", "roll", (0.0, 0.0, 1.0), ROLL_TORQUE, 2.0))
    return cases


def ci_cases() -> list[PushCase]:
    """The reduced CI set: 30 N lateral and axial at δ 2.0, the 1 rad/s hand, the roll torque."""
    keep = ("lateral +x_E 30 N δ2.0", "axial in 30 N δ2.0", "hand 1.0 rad/s δ2.0", f"roll {ROLL_TORQUE} N m δ2.0")
    return [c for c in default_cases() if c.label in keep]


def total_sim_seconds(cases: list[PushCase] | None = None, time_scale: float = 1.0) -> float:
    """Simulated seconds (s) of a set of runs if none ends early."""
    return len(default_cases() if cases is None else cases) * (PUSH_S + SETTLE_S) * time_scale


class Hand(Protocol):
    def apply(self, world: SimWorld, t: float, dt: float) -> float: ...


@dataclass
class ConstantPush:
    """A push of constant size on the handle, with ``grip_force`` (N) for ``duration`` s; it rises
    over ``rise`` s and falls over ``rise`` s before the hand lets go.

    The direction follows the shaft: ``lateral`` pushes ``magnitude`` N along ``axis`` (base frame)
    with its component along the shaft removed, ``axial`` pushes along the shaft (``axis`` picks in
    or out), ``roll`` twists ``magnitude`` N m about the shaft.
    """

    kind: Kind
    axis: np.ndarray
    magnitude: float
    grip_force: float
    duration: float
    rise: float = RISE_S

    def force_torque(self, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The full push as (force (N), torque (N m)), {B}, for the shaft direction ``d``."""
        zero = np.zeros(3)
        if self.kind == "lateral":
            return self.magnitude * across_shaft(self.axis, d), zero
        along = math.copysign(self.magnitude, float(self.axis @ d)) * d
        return (zero, along) if self.kind == "roll" else (along, zero)

    def apply(self, world: SimWorld, t: float, dt: float) -> float:
        """Set the hand wrench; returns the grip force (0 once released)."""
        if t >= self.duration:
            world.set_hand_wrench()
            return 0.0
        scale = min(1.0, (t + dt) / self.rise, (self.duration - t) / self.rise)
        force, torque = self.force_torque(world.shaft_axis()[1])
        world.set_hand_wrench(force=scale * force, torque=scale * torque)
        return self.grip_force


@dataclass
class TimedHand:
    """A :class:`SpeedDrivenHand` whose push is back to zero by ``duration`` s."""

    hand: SpeedDrivenHand
    duration: float

    def apply(self, world: SimWorld, t: float, dt: float) -> float:
        """Set the hand wrench; returns the grip force (0 once released)."""
        if t >= self.duration - self.hand.max_force / self.hand.force_rate:
            self.hand.engaged = False
        return self.hand.apply(world, t, dt)


def make_hand(case: PushCase, world: SimWorld, push_s: float, variation: WorldVariation | None = None) -> Hand:
    """The hand of ``case`` in the world's start pose, scaled by ``variation``'s surgeon
    (:meth:`WorldVariation.hand`: push, speed and grip)."""
    v = variation or WorldVariation()
    _, R_E = world.frame_pose("lap_E")
    axis = R_E @ np.asarray(case.axis, float)
    if case.kind == "speed":
        return TimedHand(v.hand(SpeedDrivenHand(axis, case.magnitude, case.grip_force)), push_s)
    return v.hand(ConstantPush(case.kind, axis, case.magnitude, case.grip_force, push_s))


@dataclass
class _Watch:
    """What a run records beside the loop's trace."""

    d0: np.ndarray
    depth0: float  # tip depth (m) beyond the unloaded incision at the start
    walls: Counter
    hit_ticks: int = 0

    def tip_depth(self, world: SimWorld) -> float:
        """Depth (m) of the scope tip beyond the *unloaded* incision point along the shaft.

        Measured from where the incision sits with no shaft load (it moves with the phantom, not
        with the wall's elastic give), like the physical RCM error: so it is the tip's depth in the
        body, the distance that matters for the tissue below. The controller's depth formula
        (:meth:`SimWorld.axis_offset`) with the simulated pose and the unloaded incision for p_R.
        """
        return world.axis_offset(world.incision_rest_position())[1]

    def tilt_deg(self, world: SimWorld) -> float:
        """Angle (deg) of the shaft from its start axis."""
        return math.degrees(axis_angle(world.shaft_axis()[1], self.d0))


def run_case(cfg: Config, case: PushCase, opts: ScenarioOptions, push_s: float, settle_s: float) -> Run:
    """One hard push from the reset pose; a safety hold or a simulation stop ends it early."""
    loop = ClosedLoop(cfg, seed=opts.seed, world=opts.world)
    world = loop.world
    watch = _Watch(world.shaft_axis()[1], 0.0, Counter())
    watch.depth0 = watch.tip_depth(world)
    hand = make_hand(case, world, push_s, opts.world)
    trace = Trace()
    stop: _Stop = {}
    reported = 0.0
    t0 = time.perf_counter()
    try:
        while loop.t < push_s + settle_s - 1e-9:
            grip_force = hand.apply(world, loop.t, CONTROL_DT)
            res = loop.step(grip_force)
            walls = tuple(str(w) for w in (res.limits_active or ()))
            watch.walls.update(set(walls))  # ticks per wall
            watch.hit_ticks += bool(walls)
            loop.record(
                trace,
                res,
                tilt_deg=watch.tilt_deg(world),
                tip_depth=watch.tip_depth(world),
                grip_force=grip_force,
                n_limits=len(walls),
            )
            if opts.progress and round(loop.t * 1000) % 100 == 0:
                opts.progress(0.1)
                reported += 0.1
    except SafetyStopError as exc:
        stop = {"kind": "safety hold", "time": exc.time, "reason": str(exc.reason)}
        # the arm has been brought to rest: its state then counts too
        stop["after"] = (
            loop.physical_rcm_error(),
            float(np.linalg.norm(world.contact_force())),
            watch.tilt_deg(world),
            watch.tip_depth(world),
        )
    except SimulationUnstableError as exc:  # also while a hold brought the arm to rest
        held = f" (during the hold: {loop.supervisor.alarm_reason})" if loop.supervisor.alarm else ""
        stop = {"kind": "simulation stopped", "time": exc.time, "reason": f"{exc.quantity} = {exc.value}{held}"}
    if opts.progress:
        opts.progress(max(0.0, push_s + settle_s - reported))
    m = _metrics(loop, trace, time.perf_counter() - t0, watch, stop, case)
    m.update(evaluate(m, cfg))
    return Run(case.label, trace, m)


def _metrics(
    loop: ClosedLoop, trace: Trace, wall: float, watch: _Watch, stop: _Stop, case: PushCase
) -> dict[str, Metric]:
    """Physical metrics of one run (mm, N, deg), the envelope hits and the alarm."""
    m: dict[str, Metric] = {
        "kind": case.kind,
        "magnitude": case.magnitude,
        "delta_nominal": case.delta,
        "grip_force_N": case.grip_force,
    }
    rcm, force, tilt, depth = [], [], [0.0], [watch.depth0]
    if "t" in trace:
        m.update(run_metrics(loop, trace, wall))
        rcm, force = [number(m, "rcm_error_max_mm")], [number(m, "trocar_force_max_N")]
        tilt.append(float(trace["tilt_deg"].max()))
        depth += [float(trace["tip_depth"].min()), float(trace["tip_depth"].max())]
        tip = trace["tip_depth"]
        n = round(END_RATE_S / CONTROL_DT)
        settled = not stop and tip.size > n  # after a hold the arm is at rest
        m["depth_rate_end_mm_s"] = float((tip[-1] - tip[-1 - n]) / END_RATE_S * 1e3) if settled else None
        delta = trace["delta"][trace["grip_force"] > 0]
        m["delta_mean"] = float(delta.mean()) if delta.size else None
    else:  # stopped on the first tick
        m.update({"duration_s": 0.0, "references_inside_limits": None, "delta_mean": None, "depth_rate_end_mm_s": None})
    after = stop.pop("after", None)
    if after is not None:  # the state once the hold brought the arm to rest
        rcm.append(after[0] * 1e3)
        force.append(after[1])
        tilt.append(after[2])
        depth.append(after[3])
    m["rcm_error_max_mm"] = max(rcm, default=None)
    m["trocar_force_max_N"] = max(force, default=None)
    m["tilt_max_deg"] = max(tilt)
    m["tip_depth_start_mm"] = watch.depth0 * 1e3
    m["tip_depth_min_mm"] = min(depth) * 1e3
    m["tip_depth_max_mm"] = max(depth) * 1e3
    m["depth_change_min_mm"] = (min(depth) - watch.depth0) * 1e3
    m["depth_change_max_mm"] = (max(depth) - watch.depth0) * 1e3
    m["envelope_hit_ticks"] = watch.hit_ticks
    m["envelope_walls"] = ", ".join(f"{k}×{n}" for k, n in watch.walls.most_common())
    m["stop"] = stop.get("kind")
    m["stop_time_s"] = stop.get("time")
    m["alarm"] = f"{stop['kind']} at {stop['time']:.3f} s: {stop['reason']}" if stop else None
    return m


def evaluate(m: dict, cfg: Config) -> dict[str, bool | str]:
    """Each target of issue 9 for one run's metrics, and the names of those it misses."""
    env = cfg.envelope
    ok = {
        "rcm_ok": m["rcm_error_max_mm"] is not None and m["rcm_error_max_mm"] <= TARGET_RCM_MM,
        "force_ok": m["trocar_force_max_N"] is not None and m["trocar_force_max_N"] <= TARGET_FORCE_N,
        "depth_ok": m["stop"] != "simulation stopped"
        and env.depth_min * 1e3 <= m["tip_depth_min_mm"]
        and m["tip_depth_max_mm"] <= env.depth_max * 1e3,
        "limits_ok": bool(m["references_inside_limits"]),
    }
    names = {"rcm_ok": "RCM", "force_ok": "force", "depth_ok": "depth", "limits_ok": "limits"}
    failed = [names[k] for k, v in ok.items() if not v]
    if m["stop"] == "simulation stopped":
        failed.append("sim stopped")
    return {**ok, "passed": not failed, "failed_targets": ", ".join(failed)}


def _still_moving(m: dict[str, Metric]) -> bool:
    """Whether the tip's depth still changed at the end of the run (its rate is None after a stop: at rest)."""
    rate = m.get("depth_rate_end_mm_s")
    return isinstance(rate, float) and abs(rate) > STILL_MOVING_MM_S


def targets(cfg: Config) -> dict[str, float]:
    """The issue's targets in report units."""
    return {
        "rcm_error_max_mm": TARGET_RCM_MM,
        "trocar_force_max_N": TARGET_FORCE_N,
        "tip_depth_min_mm": cfg.envelope.depth_min * 1e3,
        "tip_depth_max_mm": cfg.envelope.depth_max * 1e3,
    }


def hard_push(cfg: Config, opts: ScenarioOptions | None = None, cases: list[PushCase] | None = None) -> ScenarioResult:
    """Every case of ``cases`` (default: :func:`default_cases`) as an independent run."""
    opts = opts or ScenarioOptions()
    push_s, settle_s = PUSH_S * opts.time_scale, SETTLE_S * opts.time_scale
    runs = [run_case(cfg, c, opts, push_s, settle_s) for c in (default_cases() if cases is None else cases)]
    ms = [r.metrics for r in runs]
    worst = {
        k: max((float(v) for m in ms if (v := m.get(k)) is not None), default=None)
        for k in ("rcm_error_max_mm", "trocar_force_max_N", "tilt_max_deg")
    }
    return ScenarioResult(
        "hard-push",
        runs,
        {
            "runs": len(runs),
            "passed": sum(bool(m["passed"]) for m in ms),
            "alarms": sum(m["alarm"] is not None for m in ms),
            "still_moving": [r.label for r in runs if _still_moving(r.metrics)],
            "all_references_inside_limits": all(bool(m["references_inside_limits"]) for m in ms),
            "worst": worst,
            "targets": targets(cfg),
            "push_s": push_s,
            "settle_s": settle_s,
        },
    )
