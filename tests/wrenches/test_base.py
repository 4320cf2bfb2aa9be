"""Every registered cue, checked through the one :class:`~lapwrench.wrenches.base.Cue` interface
(after mink's ``test_jacobians.py``: one generic harness over every task).

For each cue installed in the ``lapwrench.cues`` entry-point group, built from the ``cues:``
section with its default parameters, on contexts captured from real controller ticks at random
states with every input present:

- its wrench is finite, and zero when the inputs it names are missing;
- the Jacobian of the point it is taken about, as the allocator uses it (J_P = [J_Eω; J_Ev - [p - p_E]x J_Eω],
  eq 34-36), matches finite differences of that body point's pose;
- moving it to p_G with eq (39) and mapping through J_G gives the torque J_Pᵀ W it would give at its
  own point (null-space cues; the RCM cue acts at p_R through J_R);
- its damping matrix, if it has one, is the wrench's derivative: W(θ̇ + h v) - W(θ̇) = -D J_G h v;
- for the paper's cues (compiled into the tick), ``compute`` gives what the compiled tick reports.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from lapwrench import plugins
from lapwrench.config import Config, from_dict
from lapwrench.controller import Controller
from lapwrench.rcm.geometry import closest_point_jacobian
from lapwrench.sensors import (
    ForceTorqueReading,
    InstrumentObservation,
    RobotReading,
    SensorFrame,
    TactileReading,
    ValidInputs,
)
from lapwrench.spatial import Wrench, wrench_transform
from lapwrench.wrenches.base import Cue, TickContext
from lapwrench.wrenches.registry import build_cues

REGISTERED = plugins.names(plugins.CUE_GROUP)
STATES = 6
# A registered cue, a few ticks' (context, the tick's wrenches by name) and a controller.
Case = tuple[Cue, list[tuple[TickContext, dict[str, np.ndarray]]], Controller]


class Probe(Cue):
    """A cue that records the context of each tick and adds nothing."""

    def __init__(self, cfg: Config) -> None:
        super().__init__("probe", None, cfg)
        self.seen: list[TickContext] = []

    def compute(self, ctx: TickContext) -> Wrench:
        self.seen.append(ctx)
        return Wrench.zero(ctx.geometry.p_G)


def _config(name: str) -> Config:
    return from_dict({"cues": {name: {}}})


def _frame(rng: np.random.Generator, q: np.ndarray, t: float) -> SensorFrame:
    """Every input present and valid: a push on the handle, a firm grip, two instruments off-centre."""
    points = rng.uniform([40.0, 40.0], [600.0, 440.0], (2, 2))
    return SensorFrame(
        t,
        ForceTorqueReading(rng.uniform(-15.0, 15.0, 3), rng.uniform(-0.5, 0.5, 3), t),
        TactileReading(np.full(64, 60.0), t),
        InstrumentObservation(points, t),
        RobotReading(q, np.zeros(q.shape[0]), np.zeros(3), t),
    )


def _ticks(cfg: Config, seed: int) -> list[tuple[TickContext, dict[str, np.ndarray]]]:
    """(context, the tick's wrenches by name) of a few ticks at random states near the home pose."""
    probe = Probe(cfg)
    ctrl = Controller(cfg, extra_cues=[probe])
    rng = np.random.default_rng(seed)
    lim = ctrl.model.limits
    home = 0.5 * (lim.position_lower + lim.position_upper)
    out = []
    for _ in range(STATES):
        q0 = home + 0.25 * (lim.position_upper - lim.position_lower) * rng.uniform(-0.5, 0.5, home.shape[0])
        ctrl.reset(q0)
        for k in range(3):  # a few ticks: the arm moves, so the damping terms see a velocity
            assert ctrl.ref is not None
            r = ctrl.tick(_frame(rng, ctrl.ref.q, k * ctrl.dt))
        out.append((probe.seen[-1], r.wrenches))
    return out


@pytest.fixture(scope="module", params=REGISTERED)
def case(request: pytest.FixtureRequest) -> Case:
    name = request.param
    cfg = _config(name)
    cue = next(c for c in build_cues(cfg) if c.name == name)
    return cue, _ticks(cfg, seed=len(name)), Controller(cfg)


def test_the_paper_cues_are_registered_like_any_plugin() -> None:
    assert {"rcm", "interaction", "tracking", "viscous"} <= set(REGISTERED)


def test_the_wrench_is_finite_and_zero_without_the_inputs_it_names(case: Case) -> None:
    cue, ticks, _ = case
    for ctx, _ in ticks:
        w = cue.compute(ctx)
        assert np.all(np.isfinite(w.vector)) and w.point.shape == (3,)
        if cue.inputs:
            bare = ValidInputs(robot=ctx.inputs.robot)
            empty = cue.compute(TickContext(ctx.time, ctx.kin, ctx.geometry, bare))
            if cue.damping_matrix(ctx) is None:
                assert np.allclose(empty.vector, 0.0), f"{cue.name} acts without its inputs {cue.inputs}"


def _body_pose(ctrl: Controller, q: np.ndarray, offset_E: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    kin = ctrl.model.kinematics(q, np.zeros(q.shape[0]))
    return kin.p_E + kin.R_E @ offset_E, kin.R_E


def test_the_point_jacobian_matches_finite_differences(case: Case) -> None:
    cue, ticks, ctrl = case
    h = 1e-6
    for ctx, _ in ticks:
        kin = ctx.kin
        p = np.asarray(cue.compute(ctx).point, dtype=float)
        if cue.priority == "task":
            continue  # p_R is a point in space, not on the scope: its Jacobian J_R has its own test (rcm/)
        offset_E = kin.R_E.T @ (p - kin.p_E)
        J = closest_point_jacobian(kin, p - kin.p_E)
        J_fd = np.zeros_like(J)
        for i in range(kin.q.shape[0]):
            dq = np.zeros(kin.q.shape[0])
            dq[i] = h
            p_plus, R_plus = _body_pose(ctrl, kin.q + dq, offset_E)
            p_minus, R_minus = _body_pose(ctrl, kin.q - dq, offset_E)
            J_fd[3:, i] = (p_plus - p_minus) / (2 * h)
            J_fd[:3, i] = Rotation.from_matrix(R_plus @ R_minus.T).as_rotvec() / (2 * h)
        np.testing.assert_allclose(J, J_fd, atol=1e-6)


def test_moving_the_wrench_to_the_closest_point_keeps_its_torque(case: Case) -> None:
    cue, ticks, _ = case
    if cue.priority == "task":
        pytest.skip("the RCM cue acts at p_R through J_R")
    for ctx, _ in ticks:
        w = cue.compute(ctx)
        kin, geo = ctx.kin, ctx.geometry
        J_P = closest_point_jacobian(kin, w.point - kin.p_E)
        at_G = wrench_transform(w.point, geo.p_G) @ w.vector
        np.testing.assert_allclose(geo.J_G.T @ at_G, J_P.T @ w.vector, atol=1e-9 * (1 + np.abs(w.vector).max()))


def test_the_damping_matrix_is_the_derivative_of_the_wrench(case: Case) -> None:
    cue, ticks, _ = case
    rng = np.random.default_rng(3)
    for ctx, _ in ticks:
        D = cue.damping_matrix(ctx)
        if D is None:
            pytest.skip(f"{cue.name} has no damping matrix")
        assert D.shape == (6, 6) and np.all(np.isfinite(D))
        v = rng.normal(size=ctx.kin.q.shape[0])
        h = 1e-4
        moved = TickContext(ctx.time, ctx.kin._replace(dq=ctx.kin.dq + h * v), ctx.geometry, ctx.inputs)
        dW = wrench_transform(cue.compute(moved).point, ctx.geometry.p_G) @ cue.compute(moved).vector
        dW -= wrench_transform(cue.compute(ctx).point, ctx.geometry.p_G) @ cue.compute(ctx).vector
        np.testing.assert_allclose(dW, -D @ ctx.geometry.J_G @ (h * v), atol=1e-9)


def test_a_compiled_cue_computes_what_the_compiled_tick_reports(case: Case) -> None:
    cue, ticks, _ = case
    if not cue.fused:
        pytest.skip(f"{cue.name} runs in Python: compute is what the tick uses")
    for ctx, wrenches in ticks:
        np.testing.assert_allclose(cue.compute(ctx).vector, wrenches[cue.name], rtol=1e-9, atol=1e-9)
