"""What SimWorld reads: trocar contact force, external torque, the ground-truth geometry."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from lapwrench.rcm.geometry import axis_rcm_error_and_depth, initial_rcm_point, insertion_depth, rcm_error
from lapwrench.robot.model import RobotModel, scope_axis
from lapwrench.sim.scene.build import incision_position_for
from lapwrench.sim.world import SimWorld


def _run(world: SimWorld, q_ref: np.ndarray, n: int) -> None:
    for _ in range(n):
        world.step(q_ref)


def test_contact_force_grows_with_incision_displacement(world: SimWorld) -> None:
    """Push the phantom sideways: the wall deflects and presses on the shaft, F ~ k_wall * deflection."""
    q0 = world.scene.q0
    k_wall = world.scene.config.phantom.wall_stiffness
    _run(world, q0, 50)
    assert np.linalg.norm(world.contact_force()) < 1e-6, "shaft at the unloaded incision: no force"
    forces = []
    for load in (8.0, 16.0, 32.0):
        world.reset()
        world.set_housing_load(np.array([0.0, load, 0.0]))
        _run(world, q0, 1200)
        f = world.contact_force()
        defl = world.incision_deflection()
        forces.append(np.linalg.norm(f))
        # The wall drags the scope along the load; the scope pushes the incision back.
        assert f[1] > 0 and abs(f[0]) < 1e-3 * np.linalg.norm(f)
        assert np.linalg.norm(f) == pytest.approx(k_wall * np.linalg.norm(defl), rel=0.03)
        assert world.rcm_error() < 1e-4  # the trocar weld is stiff: tens of micrometres
    assert forces[0] < forces[1] < forces[2]
    assert forces[2] > 5.0


def test_contact_force_is_smooth_under_moving_load(world: SimWorld) -> None:
    q0 = world.scene.q0
    fs = []
    for i in range(1500):
        t = i * 1e-3
        ang = 2 * np.pi * 0.8 * t
        world.set_housing_load(30.0 * min(t / 0.3, 1.0) * np.array([np.cos(ang), np.sin(ang), 0.0]))
        world.step(q0)
        fs.append(world.contact_force())
    fs = np.array(fs)
    jumps = np.linalg.norm(np.diff(fs, axis=0), axis=1)
    assert np.max(np.linalg.norm(fs, axis=1)) > 4.0
    assert np.max(jumps) < 0.2, f"contact force jumps by {np.max(jumps):.3f} N in 1 ms"


def test_external_torque_matches_loads(world: SimWorld) -> None:
    """tau_ext = J_H^T w_hand + J_c^T F_contact, and M ddq + c + g = tau_J + tau_ext (rigid model)."""
    q0 = world.scene.q0
    f_hand, tau_hand = np.array([3.0, -2.0, 1.0]), np.array([0.05, -0.1, 0.08])
    world.set_hand_wrench(force=f_hand, torque=tau_hand)
    world.set_housing_load(np.array([10.0, 5.0, 0.0]))
    _run(world, q0, 300)
    m, d = world.model, world.data
    v = world.scene.arm_dof_adr
    jp = np.zeros((3, m.nv))
    jr = np.zeros((3, m.nv))
    mujoco.mj_jacBody(m, d, jp, jr, m.body("lap_H").id)
    expected = jp[:, v].T @ f_hand + jr[:, v].T @ tau_hand
    f_c = world.contact_force()
    assert np.linalg.norm(f_c) > 0.5
    jc = np.zeros((3, m.nv))
    mujoco.mj_jac(m, d, jc, None, world.incision_position(), m.body("lap_shaft").id)
    expected += jc[:, v].T @ f_c
    # The weld also transmits the (tiny) torque that turns the light trocar: allow 1 mN m.
    np.testing.assert_allclose(world.external_torque(), expected, atol=1e-3)
    # Link-side torque closes the rigid-body dynamics without armature.
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    M_arm = M[np.ix_(v, v)] - np.diag(m.dof_armature[v])
    lhs = M_arm @ d.qacc[v] + d.qfrc_bias[v]
    np.testing.assert_allclose(lhs, world.joint_torque_measured() + world.external_torque(), atol=1e-6)
    np.testing.assert_allclose(world.hand_force(), f_hand)
    np.testing.assert_allclose(world.hand_torque(), tau_hand)


def test_ground_truth_is_the_controllers_geometry_at_the_simulated_pose(world: SimWorld) -> None:
    """The simulator's RCM error and tip depth (:meth:`SimWorld.axis_offset`) are eq (27) and the
    depth of :mod:`lapwrench.rcm.geometry` on the controller model's scope axis at the world's joints,
    and the incision starts at eq (18)'s p_R(t0): MuJoCo and Pinocchio agree on lap_E."""
    cfg = world.scene.config
    model = RobotModel(cfg.kind)
    assert model.length == cfg.scope.length
    kin0 = model.kinematics(world.scene.q0, np.zeros(7))
    np.testing.assert_allclose(
        incision_position_for(cfg), initial_rcm_point(kin0, cfg.scope.length, cfg.rcm_lambda0), atol=1e-9
    )
    _run(world, world.scene.q0 + np.array([0.05, -0.03, 0.04, 0.02, -0.05, 0.03, 0.2]), 200)
    kin = model.kinematics(world.q, np.zeros(7))
    rng = np.random.default_rng(4)
    for _ in range(10):
        p = world.incision_rest_position() + rng.normal(scale=0.01, size=3)
        e, depth = world.axis_offset(p)
        assert e == pytest.approx(np.linalg.norm(rcm_error(kin, p)), abs=1e-9)
        assert depth == pytest.approx(insertion_depth(kin, p, cfg.scope.length), abs=1e-9)
    assert world.rcm_error() == world.axis_offset(world.incision_position())[0]
    # one compiled call, the same numbers as eq (27)'s kernels called one after the other on MuJoCo's lap_E pose
    p_E, R_E = world.frame_pose("lap_E")
    d_z, P = scope_axis(np.ascontiguousarray(R_E))
    for p in (world.incision_rest_position(), [0.4, -0.1, 0.3]):
        assert world.axis_offset(p) == axis_rcm_error_and_depth(p_E, d_z, P, np.asarray(p, float), cfg.scope.length)
