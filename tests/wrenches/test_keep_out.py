"""The keep-out cue (lapwrench.wrenches.keep_out): a barrier and damping that keep the scope tip out
of a sphere or a half-space."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.config import ConfigError, from_dict
from lapwrench.rcm.geometry import TaskGeometry
from lapwrench.robot.model import Kinematics
from lapwrench.sensors import ValidInputs
from lapwrench.spatial import wrench_transform
from lapwrench.wrenches.base import TickContext
from lapwrench.wrenches.keep_out import (
    KeepOutCue,
    KeepOutParams,
    barrier_force,
    plane_distance,
    sphere_distance,
    tip_velocity_map,
)
from lapwrench.wrenches.registry import build_cues

N = 7  # joints of the synthetic context
P_G = np.array([0.5, 0.0, 0.25])


def _context(p_C: np.ndarray, dq: np.ndarray | None = None, seed: int = 0) -> TickContext:
    """A tick context with the tip at ``p_C``, p_G above it and a random closest-point Jacobian."""
    z3 = np.zeros(3)
    J_G = np.random.default_rng(seed).normal(size=(6, N))
    dq = np.zeros(N) if dq is None else dq
    kin = Kinematics(np.zeros(N), dq, np.eye(N), np.zeros(N), np.zeros(N), np.array([0.5, 0.0, 0.5]), np.eye(3),
                     np.zeros((6, N)), z3, np.eye(3), np.asarray(p_C, float), np.eye(3), np.array([0.0, 0.0, -1.0]),
                     np.diag([1.0, 1.0, 0.0]), np.zeros(6))
    geo = TaskGeometry(z3, z3, z3, z3, np.zeros((3, N)), 0.0, P_G, z3, J_G, z3)
    return TickContext(0.0, kin, geo, ValidInputs())


def _cue(**params: object) -> KeepOutCue:
    cfg = from_dict({"cues": {"keep_out": params}})
    return next(c for c in build_cues(cfg) if isinstance(c, KeepOutCue))


SPHERE = {"center": [0.45, 0.0, 0.2], "radius": 0.03, "margin": 0.01, "stiffness": 1e4, "F_max": 60.0}


def test_sphere_distance_is_signed_with_an_outward_normal() -> None:
    c = np.array([1.0, 2.0, 3.0])
    d, n = sphere_distance(c + np.array([0.0, 0.05, 0.0]), c, 0.03)
    assert d == pytest.approx(0.02) and np.allclose(n, [0.0, 1.0, 0.0])
    d, n = sphere_distance(c + np.array([0.0, 0.0, -0.01]), c, 0.03)
    assert d == pytest.approx(-0.02) and np.allclose(n, [0.0, 0.0, -1.0])


def test_plane_distance_is_signed_along_the_normalised_normal() -> None:
    d, n = plane_distance(np.array([0.0, 0.0, 0.3]), np.array([0.0, 0.0, 0.1]), np.array([0.0, 0.0, 2.0]))
    assert d == pytest.approx(0.2) and np.allclose(n, [0.0, 0.0, 1.0])
    assert plane_distance(np.array([5.0, 1.0, 0.05]), np.array([0.0, 0.0, 0.1]), np.array([0.0, 0.0, 1.0]))[0] < 0


def test_barrier_is_zero_beyond_the_margin_grows_inside_and_is_capped() -> None:
    assert barrier_force(0.011, 0.01, 1e4, 60.0) == 0.0
    assert barrier_force(0.01, 0.01, 1e4, 60.0) == 0.0
    assert barrier_force(0.005, 0.01, 1e4, 60.0) == pytest.approx(50.0)
    assert barrier_force(0.0, 0.01, 1e4, 60.0) == pytest.approx(60.0)
    assert barrier_force(-0.02, 0.01, 1e4, 60.0) == pytest.approx(60.0)


def test_no_wrench_and_no_damping_away_from_the_zone() -> None:
    cue = _cue(**SPHERE)
    ctx = _context(np.array([0.5, 0.0, 0.2]), dq=np.ones(N))  # 20 mm from the sphere, margin 10
    assert not np.any(cue.compute(ctx).vector)
    assert cue.damping_matrix(ctx) is None
    assert cue.telemetry(ctx, cue.compute(ctx)) == (pytest.approx(0.02), 0.0)


def test_in_the_margin_the_tip_is_pushed_out_along_the_normal() -> None:
    cue = _cue(**SPHERE)
    p_C = np.array([0.485, 0.0, 0.2])  # 5 mm from the sphere's surface, on its +x side
    ctx = _context(p_C)
    w = cue.compute(ctx)
    assert np.allclose(w.point, P_G)
    at_tip = wrench_transform(P_G, p_C) @ w.vector  # the same wrench about the tip: a pure force
    assert np.allclose(at_tip[:3], 0.0, atol=1e-12)
    assert np.allclose(at_tip[3:], [50.0, 0.0, 0.0])
    assert cue.telemetry(ctx, w) == (pytest.approx(0.005), pytest.approx(50.0))


def test_each_tick_sees_its_own_tip() -> None:
    """One cue, the tip moving in and out of the layer: wrench, damping and telemetry follow each context."""
    cue = _cue(**SPHERE)
    near = _context(np.array([0.485, 0.0, 0.2]), dq=np.ones(N))  # 5 mm from the sphere, margin 10
    far = _context(np.array([0.5, 0.0, 0.2]), dq=np.ones(N))  # 20 mm
    for ctx, d in ((near, 0.005), (far, 0.02), (near, 0.005), (far, 0.02)):
        w = cue.compute(ctx)
        assert bool(np.any(w.vector)) is (d < 0.01)
        assert (cue.damping_matrix(ctx) is not None) is (d < 0.01)
        assert cue.telemetry(ctx, w)[0] == pytest.approx(d)


def test_inside_the_zone_the_push_is_capped_and_still_outward() -> None:
    cue = _cue(**SPHERE)
    p_C = np.array([0.45, 0.0, 0.185])  # 15 mm below the centre: inside
    w = cue.compute(_context(p_C))
    force = (wrench_transform(P_G, p_C) @ w.vector)[3:]
    assert np.allclose(force, [0.0, 0.0, -60.0])
    assert cue.telemetry(_context(p_C), w)[0] == pytest.approx(-0.015)


def test_a_plane_zone_pushes_toward_its_allowed_side() -> None:
    cue = _cue(shape="plane", point=[0.0, 0.0, 0.1], normal=[0.0, 0.0, 1.0], margin=0.01, stiffness=1e4)
    w = cue.compute(_context(np.array([0.5, 0.0, 0.104])))  # 4 mm above the plane
    assert np.allclose(w.force, [0.0, 0.0, 60.0])


@pytest.mark.parametrize("seed", range(3))
def test_damping_is_the_normal_tip_velocity_and_matches_its_matrix(seed: int) -> None:
    cue = _cue(**SPHERE, damping=300.0)
    p_C = np.array([0.485, 0.0, 0.2])
    dq = np.random.default_rng(100 + seed).normal(size=N)
    ctx, still = _context(p_C, dq, seed), _context(p_C, None, seed)
    D = cue.damping_matrix(ctx)
    assert D is not None and D.shape == (6, 6) and np.allclose(D, D.T)
    assert np.linalg.eigvalsh(D).min() > -1e-9  # dissipative
    twist = ctx.geometry.J_G @ dq
    damping = cue.compute(ctx).vector - cue.compute(still).vector
    assert np.allclose(damping, -D @ twist)  # the wrench's viscous part is -D J_G dq
    v_C = tip_velocity_map(p_C, P_G) @ twist
    n = np.array([1.0, 0.0, 0.0])
    at_tip = wrench_transform(P_G, p_C) @ damping
    assert np.allclose(at_tip[3:], -300.0 * (n @ v_C) * n) and np.allclose(at_tip[:3], 0.0, atol=1e-9)


def test_tip_velocity_map_is_the_rigid_body_velocity() -> None:
    p_C = np.array([0.1, 0.2, 0.3])
    omega, v_G = np.array([0.0, 0.0, 2.0]), np.array([1.0, 0.0, 0.0])
    expected = v_G + np.cross(omega, p_C - P_G)
    assert np.allclose(tip_velocity_map(p_C, P_G) @ np.concatenate([omega, v_G]), expected)


def test_parameters_come_from_the_cues_section() -> None:
    cue = _cue(shape="plane", point=[0.1, 0.2, 0.3], normal=[0.0, 1.0, 0.0])
    assert cue.params == KeepOutParams(shape="plane", point=(0.1, 0.2, 0.3), normal=(0.0, 1.0, 0.0))
    assert cue.priority == "null" and cue.inputs == ()


@pytest.mark.parametrize(
    ("params", "where"),
    [
        ({"shape": "cube"}, "cues.keep_out.shape"),
        ({"radius": 0.0}, "cues.keep_out.radius"),
        ({"radius": 2.0}, "cues.keep_out.radius"),
        ({"center": [0.5, 0.0]}, "cues.keep_out.center"),
        ({"center": [0.5, 0.0, 9.0]}, "cues.keep_out.center[2]"),
        ({"shape": "plane", "normal": [0.0, 0.0, 0.0]}, "normal"),
        ({"margin": 0.5}, "cues.keep_out.margin"),
        ({"F_max": -1.0}, "cues.keep_out.F_max"),
        ({"damping": "lots"}, "cues.keep_out.damping"),
        ({"enabled": "yes"}, "cues.keep_out.enabled"),
    ],
)
def test_bad_parameters_are_one_line_config_errors(params: dict, where: str) -> None:
    with pytest.raises(ConfigError) as err:
        from_dict({"cues": {"keep_out": params}})
    assert "\n" not in str(err.value) and where in str(err.value)
