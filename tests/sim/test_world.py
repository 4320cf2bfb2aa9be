"""Robot in the loop: joint servo tracking, incision contact, loads, instability detection."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from lapwrench.sim.scene import SceneConfig
from lapwrench.sim.world import JointServoGains, SimulationUnstableError, SimWorld


def _run(world: SimWorld, q_ref: np.ndarray, n: int) -> None:
    for _ in range(n):
        world.step(q_ref)


def test_worlds_sharing_a_scene_keep_their_own_gains(panda_scene) -> None:
    soft = JointServoGains(stiffness=(300.0,) * 7, damping=(10.0,) * 7)
    a = SimWorld(panda_scene, gains=soft)
    b = SimWorld(panda_scene)
    assert a.model.actuator_gainprm[0, 0] == 300.0 and b.model.actuator_gainprm[0, 0] == 3000.0


def test_timing(world: SimWorld) -> None:
    assert world.timestep == pytest.approx(0.0005)
    assert world.n_substeps == 2
    world.step(world.scene.q0)
    assert world.time == pytest.approx(0.001)


def test_static_reference_is_held(world: SimWorld) -> None:
    q_ref = world.scene.q0 + np.array([0.01, -0.01, 0.01, 0.01, -0.02, 0.01, 0.3])
    world.reset(q_ref)
    assert world.rcm_error() < 1e-9, "reset puts the trocar on the shaft axis"
    f0 = np.linalg.norm(world.contact_force())
    assert 1.0 < f0 < 15.0, "the shaft starts off the unloaded incision: the wall pushes"
    _run(world, q_ref, 500)
    assert np.max(np.abs(world.q - q_ref)) < 2e-3
    assert np.max(np.abs(world.dq)) < 1e-2
    tau = world.motor_torque()
    assert np.all(np.abs(tau) <= np.array([87.0] * 4 + [12.0] * 3) + 1e-9)


def test_slow_sinusoid_is_followed(world: SimWorld) -> None:
    """0.5 Hz motion; the error includes the wall's push (the shaft moves ~1 cm at the incision)."""
    q0 = world.scene.q0
    amp = np.array([0.02, 0.02, 0.02, 0.03, 0.05, 0.03, 0.1])
    errs = []
    for _ in range(1500):
        t = world.time + 0.001
        world.step(q0 + amp * np.sin(2 * np.pi * 0.5 * t))
        if t > 0.3:
            errs.append(np.abs(world.q - world.q_ref))
    assert np.max(errs) < 5e-3
    assert np.max(np.abs(np.array(errs)[:, 6])) < 1e-3  # roll about the shaft: no wall load


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
    w_hand = np.array([3.0, -2.0, 1.0, 0.05, -0.1, 0.08])
    world.set_hand_wrench(w_hand)
    world.set_housing_load(np.array([10.0, 5.0, 0.0]))
    _run(world, q0, 300)
    m, d = world.model, world.data
    v = world.scene.arm_dof_adr
    jp = np.zeros((3, m.nv))
    jr = np.zeros((3, m.nv))
    mujoco.mj_jacBody(m, d, jp, jr, m.body("lap_H").id)
    expected = np.vstack([jp, jr])[:, v].T @ w_hand
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
    np.testing.assert_allclose(world.hand_wrench(), w_hand)


def test_hand_push_and_disturbance_stay_stable_fr3() -> None:
    """FR3 (light link 7): 2 s of hand push plus a 10 mm housing shift, no blow-up."""
    w = SimWorld(SceneConfig(kind="fr3"))
    q0 = w.scene.q0
    peak = 0.0
    for i in range(2000):
        if i == 200:
            w.set_hand_wrench(np.array([0.0, 8.0, 0.0, 0.0, 0.0, 0.3]))
        if i == 800:
            w.set_housing_load(np.array([35.0, 0.0, 0.0]))
        w.step(q0)
        peak = max(peak, float(np.linalg.norm(w.contact_force())))
    assert np.all(np.isfinite(w.q))
    assert 5.0 < peak < 60.0
    assert np.linalg.norm(w.housing_displacement()) > 0.008


def test_instruments_pass_through_ports(world: SimWorld) -> None:
    tip = world.incision_position() + np.array([0.01, 0.02, -0.12])
    world.set_instrument_tip(0, tip)
    world.step(world.scene.q0)
    np.testing.assert_allclose(world.instrument_tip(0), tip)
    port = world.port_position(0)
    R = world.data.xmat[world.model.body("instrument_left").id].reshape(3, 3)
    axis = R[:, 2]
    r = port - tip
    assert np.linalg.norm(r - (r @ axis) * axis) < 1e-9, "shaft axis passes through the port"
    assert (tip - port) @ axis > 0.1
    _uv, z = world.project_to_image(tip)
    assert z > 0
    assert world.n_instruments == 2  # the paper's two instruments, each through its own port
    assert np.linalg.norm(world.port_position(1) - port) > 0.05


def test_instability_detector_fires_on_nan(world: SimWorld) -> None:
    world.step(world.scene.q0)
    world.data.qvel[world.scene.arm_dof_adr[3]] = np.nan
    with pytest.raises(SimulationUnstableError, match=r"t = 0\.0010 s.*qpos/qvel") as info:
        world.step(world.scene.q0)
    assert info.value.time == pytest.approx(0.001)


def test_instability_detector_fires_on_mujoco_divergence(world: SimWorld) -> None:
    world.step(world.scene.q0)
    world.data.qvel[world.scene.arm_dof_adr[0]] = 1e12  # MuJoCo resets on |qvel| > 1e10 and warns
    with pytest.raises(SimulationUnstableError, match="MuJoCo state"):
        world.step(world.scene.q0)


def test_instability_detector_fires_on_contact_blowup(panda_scene) -> None:
    w = SimWorld(panda_scene, max_contact_force=3.0)
    w.set_housing_load(np.array([0.0, 40.0, 0.0]))
    with pytest.raises(SimulationUnstableError, match="contact force") as info:
        for _ in range(2000):
            w.step(w.scene.q0)
    assert info.value.quantity.startswith("shaft-incision contact force")
    assert 0.0 < info.value.time < 2.0


def test_bad_inputs_raise(world: SimWorld) -> None:
    with pytest.raises(SimulationUnstableError, match="q_ref"):
        world.step(np.full(7, np.nan))
    with pytest.raises(ValueError, match="hand wrench"):
        world.set_hand_wrench(np.zeros(5))
    with pytest.raises(ValueError, match="housing load"):
        world.set_housing_load(np.array([np.inf, 0.0, 0.0]))


def test_scope_beyond_the_trocar_is_reported(world: SimWorld) -> None:
    """A pose whose shaft would end above the incision is outside the trocar model: a clear error."""
    world.reset(world.scene.q0 + np.array([0.0, 0.1, 0.0, 0.25, 0.0, 0.15, 0.0]))
    assert world.insertion_depth() > world.scene.config.scope.length
    with pytest.raises(SimulationUnstableError, match=r"insertion depth"):
        world.step(world.q)


def test_housing_load_for_a_10mm_shift(world: SimWorld) -> None:
    """Fig. 5 disturbance: the helper's load shifts the housing ~10 mm with the scope holding."""
    load = world.housing_load_for_shift(np.array([0.0, 0.01]))
    world.set_housing_load(load)
    _run(world, world.scene.q0, 1500)
    assert world.housing_displacement()[1] == pytest.approx(0.01, abs=0.0015)
    assert 5.0 < np.linalg.norm(world.contact_force()) < 12.0
