"""Robot in the loop: joint servo tracking, incision contact, loads, instability detection."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import mujoco
import numpy as np
import pytest

from lapwrench.rcm.geometry import initial_rcm_point, insertion_depth, rcm_error
from lapwrench.robot.description import ARM_SPECS
from lapwrench.robot.model import RobotModel
from lapwrench.sim.scene.build import incision_position_for
from lapwrench.sim.scene.config import SceneConfig
from lapwrench.sim.scene.instruments import _instrument_pose_through_port_numpy, instrument_pose_through_port
from lapwrench.sim.world import CONTROL_DT, JointServoGains, SimulationUnstableError, SimWorld
from lapwrench.sim.world.model_facts import _mocap_is_inert


def _run(world: SimWorld, q_ref: np.ndarray, n: int) -> None:
    for _ in range(n):
        world.step(q_ref)


def test_worlds_sharing_a_scene_keep_their_own_gains(panda_scene) -> None:
    soft = JointServoGains(stiffness=(300.0,) * 7, damping=(10.0,) * 7)
    a = SimWorld(panda_scene, gains=soft)
    b = SimWorld(panda_scene)
    assert a.model.actuator_gainprm[0, 0] == 300.0 and b.model.actuator_gainprm[0, 0] == 3000.0


def test_the_servo_gains_are_the_robots_and_one_per_joint(panda_scene) -> None:
    spec = ARM_SPECS["panda"]
    w = SimWorld(panda_scene)
    assert w.n_joints == spec.n_joints and w.gains == JointServoGains.for_robot("panda")
    act = [w.model.actuator(f"servo_{n}").id for n in w.scene.arm_joint_names]
    assert w.model.actuator_gainprm[act, 0].tolist() == list(spec.servo_stiffness)
    short = JointServoGains(stiffness=spec.servo_stiffness[:-1], damping=spec.servo_damping[:-1])
    with pytest.raises(ValueError, match=f"{spec.n_joints} joints"):
        SimWorld(panda_scene, gains=short)
    with pytest.raises(ValueError, match="differ in length"):
        JointServoGains(stiffness=spec.servo_stiffness, damping=spec.servo_damping[:-1])


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


def test_hand_push_and_disturbance_stay_stable_fr3() -> None:
    """FR3 (light link 7): 2 s of hand push plus a 10 mm housing shift, no blow-up."""
    w = SimWorld(SceneConfig(kind="fr3"))
    q0 = w.scene.q0
    peak = 0.0
    for i in range(2000):
        if i == 200:
            w.set_hand_wrench(force=[0.0, 8.0, 0.0], torque=[0.0, 0.0, 0.3])
        if i == 800:
            w.set_housing_load(np.array([35.0, 0.0, 0.0]))
        w.step(q0)
        peak = max(peak, float(np.linalg.norm(w.contact_force())))
    assert np.all(np.isfinite(w.q))
    assert 5.0 < peak < 60.0
    assert np.linalg.norm(w.housing_displacement()) > 0.008


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
    with pytest.raises(ValueError, match="hand force"):
        world.set_hand_wrench(force=np.zeros(5))
    with pytest.raises(ValueError, match="hand torque"):
        world.set_hand_wrench(force=np.zeros(3), torque=[0.0, np.nan, 0.0])
    with pytest.raises(TypeError):
        world.set_hand_wrench(np.zeros(6))  # type: ignore[misc]  # no unnamed 6-vector: force and torque by name
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


# ---------------------------------------------------------------------------------------------
# The compiled tick against the straightforward one


class _PlainStep:
    """SimWorld.step as first written: numpy on fresh MjData lookups, a full mj_step per substep."""

    def __init__(self, world: SimWorld) -> None:
        self.w = world
        self.q_prev = world.q_ref

    def step(self, q_ref: np.ndarray, dq_ref: np.ndarray | None = None) -> np.ndarray:
        w, m, d = self.w, self.w.model, self.w.data
        v = w.scene.arm_dof_adr
        kp, kv = np.asarray(w.gains.stiffness, float), np.asarray(w.gains.damping, float)
        if dq_ref is None:
            dq_ref = (q_ref - self.q_prev) / CONTROL_DT
        self.q_prev = q_ref.copy()
        act = [m.actuator(f"servo_{n}").id for n in w.scene.arm_joint_names]
        d.ctrl[act] = q_ref + (kv / kp) * dq_ref
        total = np.zeros(7)
        v_tick = d.qvel[v].copy()
        armature, damping = m.dof_armature[v], m.dof_damping[v]
        for _ in range(w.n_substeps):
            v_start = d.qvel[v].copy()
            mujoco.mj_step(m, d)
            tau = d.qfrc_actuator[v]
            kv_eff = kv * (np.abs(tau) < np.array([87.0] * 4 + [12.0] * 3) - 1e-9)
            total += tau + d.qfrc_damper[v] - (kv_eff + damping) * (d.qvel[v] - v_start)
        tick = w.n_substeps * m.opt.timestep
        tau_mean = total / w.n_substeps - armature * (d.qvel[v] - v_tick) / tick
        mujoco.mj_forward(m, d)
        return tau_mean


def _plain_contact_force(world: SimWorld) -> np.ndarray:
    d = world.data
    weld = world.model.equality("trocar_weld").id
    rows = np.flatnonzero(
        (d.efc_type[: d.nefc] == mujoco.mjtConstraint.mjCNSTR_EQUALITY) & (d.efc_id[: d.nefc] == weld)
    )
    return np.zeros(3) if rows.size < 3 else -d.efc_force[rows[:3]]


def _script(world: SimWorld, i: int) -> tuple[np.ndarray, np.ndarray | None]:
    """Scripted loads and references of tick ``i`` (instrument moved, hand and housing loads, dq_ref)."""
    t = (i + 1) * CONTROL_DT
    if i == 100:
        world.set_hand_wrench(force=[4.0, -2.0, 1.0], torque=[0.0, 0.05, 0.1])
    if i == 250:
        world.set_housing_load(world.housing_load_for_shift(np.array([0.004, -0.003])))
    if i % 3 == 0:
        world.set_instrument_tip(1, world.port_position(1) + np.array([0.02, 0.06 * np.sin(t), -0.12]))
    amp = np.array([0.02, 0.02, 0.02, 0.03, 0.05, 0.03, 0.3])
    q_ref = world.scene.q0 + amp * np.sin(2 * np.pi * 1.5 * t) * min(1.0, t / 0.1)
    dq_ref = amp * 2 * np.pi * 1.5 * np.cos(2 * np.pi * 1.5 * t) if 300 <= i < 350 else None
    return q_ref, dq_ref


def test_compiled_step_matches_the_plain_step_bit_for_bit(panda_scene) -> None:
    """The kernels, the cached views and the reused first-substep forward change no bit of the
    trajectory: state, tick-mean torque, sensors, contact force and readings are identical."""
    fast, plain = SimWorld(panda_scene), SimWorld(panda_scene)
    ref = _PlainStep(plain)
    for i in range(500):
        if i == 400:
            q = panda_scene.q0 + 0.02
            fast.reset(q)
            plain.reset(q)
            ref.q_prev = plain.q_ref
        q_ref, dq_ref = _script(fast, i)
        _script(plain, i)
        fast.step(q_ref, dq_ref)
        tau_mean = ref.step(q_ref, dq_ref)
        for name in ("qpos", "qvel", "qacc", "sensordata", "efc_force", "xpos", "mocap_quat", "ctrl"):
            np.testing.assert_array_equal(getattr(fast.data, name), getattr(plain.data, name), err_msg=name)
        np.testing.assert_array_equal(fast.joint_torque_tick_mean(), tau_mean)
        np.testing.assert_array_equal(fast.contact_force(), _plain_contact_force(plain))
    assert np.linalg.norm(fast.contact_force()) > 1.0


def test_first_substep_reuses_the_closing_forward_only_when_the_state_is_unchanged(world, monkeypatch) -> None:
    calls = {"mj_step2": 0}
    real = mujoco.mj_step2

    def counting(m, d):
        calls["mj_step2"] += 1
        real(m, d)

    monkeypatch.setattr(mujoco, "mj_step2", counting)
    q0 = world.scene.q0
    for _ in range(5):
        world.step(q0)
    assert calls["mj_step2"] == 5
    world.set_instrument_tip(0, world.port_position(0) + np.array([0.0, 0.02, -0.1]))  # inert mocap
    world.set_hand_wrench(force=[1.0, 0.0, 0.0])  # acts in mj_step2 anyway
    world.step(q0)
    assert calls["mj_step2"] == 6
    world.data.qvel[world.scene.arm_dof_adr[2]] += 1e-3  # the caller moved the state: full mj_step
    world.step(q0)
    assert calls["mj_step2"] == 6
    world.step(q0)
    assert calls["mj_step2"] == 7
    world.data.eq_active[0] = 0  # constraint switched off
    world.step(q0)
    assert calls["mj_step2"] == 7
    world.data.eq_active[0] = 1
    world.reset()
    world.step(q0)
    assert calls["mj_step2"] == 8


def test_mocap_inertness() -> None:
    assert _mocap_is_inert(SimWorld().model)  # the instruments only show
    base = """<mujoco><worldbody>
      <body name="a" mocap="true"><geom size=".01" {geom}/><site name="s"/></body>
      <body name="b"><freejoint/><geom size=".01" contype="0" conaffinity="0"/></body>
      </worldbody>{extra}</mujoco>"""
    inert = base.format(geom='contype="0" conaffinity="0"', extra="")
    assert _mocap_is_inert(mujoco.MjModel.from_xml_string(inert))
    touching = base.format(geom="", extra="")
    assert not _mocap_is_inert(mujoco.MjModel.from_xml_string(touching))
    welded = base.format(geom='contype="0" conaffinity="0"', extra='<equality><weld body1="a" body2="b"/></equality>')
    assert not _mocap_is_inert(mujoco.MjModel.from_xml_string(welded))
    pulled = base.format(
        geom='contype="0" conaffinity="0"',
        extra='<actuator><general site="s" refsite="s"/></actuator>',
    )
    assert not _mocap_is_inert(mujoco.MjModel.from_xml_string(pulled))


def test_cached_ids_and_views_read_what_fresh_lookups_read(world: SimWorld) -> None:
    q0 = world.scene.q0
    world.set_hand_wrench(force=[2.0, 1.0, -1.0], torque=[0.0, 0.0, 0.02])
    for i in range(50):
        world.step(q0 + 0.01 * np.sin(i * 0.1))
    m, d = world.model, world.data
    qadr, vadr = world.scene.arm_qpos_adr, world.scene.arm_dof_adr
    np.testing.assert_array_equal(world.q, d.qpos[qadr])
    np.testing.assert_array_equal(world.dq, d.qvel[vadr])
    np.testing.assert_array_equal(world.motor_torque(), d.qfrc_actuator[vadr])
    arm = m.dof_armature[vadr]
    np.testing.assert_array_equal(
        world.joint_torque_measured(), d.qfrc_actuator[vadr] + d.qfrc_damper[vadr] - arm * d.qacc[vadr]
    )
    for body in ("lap_E", "lap_H", "lap_C", "housing"):
        p, R = world.frame_pose(body)
        b = m.body(body).id
        np.testing.assert_array_equal(p, d.xpos[b])
        np.testing.assert_array_equal(R, d.xmat[b].reshape(3, 3))
    p, dz = world.shaft_axis()
    np.testing.assert_array_equal(dz, d.xmat[m.body("lap_E").id].reshape(3, 3)[:, 2])
    np.testing.assert_array_equal(world.incision_position(), d.xpos[m.body("incision").id])
    np.testing.assert_array_equal(world.contact_force(), _plain_contact_force(world))
    xfrc_H = d.xfrc_applied[m.body("lap_H").id]  # MuJoCo's row: [force; torque]
    np.testing.assert_array_equal(world.hand_force(), xfrc_H[:3])
    np.testing.assert_array_equal(world.hand_torque(), xfrc_H[3:])
    np.testing.assert_array_equal(world.port_position(1), d.site_xpos[m.site("port_right").id])
    d.eq_active[0] = 0  # no weld rows: no force
    mujoco.mj_forward(m, d)
    np.testing.assert_array_equal(world.contact_force(), np.zeros(3))


def test_instrument_pose_matches_the_numpy_formula_bit_for_bit() -> None:
    rng = np.random.default_rng(4)
    for i in range(2000):
        port = rng.normal(size=3) * 0.1
        step = rng.normal(size=3) if i % 3 else np.array([1e-3, -2e-3, -0.1])  # near-vertical shafts too
        tip = port + step * rng.uniform(0.002, 0.3)
        roll = rng.uniform(-3.0, 3.0) if i % 2 else 0.0
        pos, quat = instrument_pose_through_port(port, tip, roll)
        pos_ref, quat_ref = _instrument_pose_through_port_numpy(port, tip, roll)
        np.testing.assert_array_equal(pos, pos_ref)
        np.testing.assert_array_equal(quat, quat_ref)
    with pytest.raises(ValueError, match="coincides"):
        instrument_pose_through_port(np.zeros(3), np.full(3, 1e-8))


def test_bad_velocity_references_raise(world: SimWorld) -> None:
    q0 = world.scene.q0
    with pytest.raises(SimulationUnstableError, match="dq_ref"):
        world.step(q0, np.array([0.0, np.inf, 0, 0, 0, 0, 0]))
    with pytest.raises(SimulationUnstableError, match="dq_ref"):
        world.step(q0, np.zeros(6))
    with pytest.raises(SimulationUnstableError, match="q_ref"):
        world.step(np.zeros(6))
    with pytest.raises(SimulationUnstableError, match="q_ref"):
        world.step(np.full(7, np.nan), np.zeros(6))
    assert world.time == 0.0
    world.step(q0[::-1][::-1], np.zeros(7)[::2].repeat(2)[:7])  # non-contiguous views are fine
    assert world.time == pytest.approx(0.001)
    frozen = q0.copy()
    frozen.flags.writeable = False
    world.step(frozen, np.zeros((2, 7))[1])  # so are read-only arrays, lists and other dtypes
    world.step([float(x) for x in q0], np.zeros(7, dtype=np.float32))
    np.testing.assert_array_equal(world.q_ref, q0)
    assert world.time == pytest.approx(0.003)


_UNCOMPILED_RUN = """
import json, sys
import numpy as np
from lapwrench.sim.robot import ForceEstimateConfig, SimRobot
from lapwrench.sim.world import SimWorld
w = SimWorld()
r = SimRobot(w, estimate=ForceEstimateConfig(torque_noise=0.05, torque_bias=0.1, seed=3))
r.connect()
w.set_hand_wrench(force=np.array([3.0, -1.0, 0.5]))
out = []
for i in range(150):
    if i % 5 == 0:
        w.set_instrument_tip(0, w.port_position(0) + np.array([0.0, 0.03 * np.sin(i / 50), -0.12]))
    r.command(w.scene.q0 + 0.02 * np.sin(i / 30))
    rd = r.read()
    out.append([*w.data.qpos, *w.joint_torque_tick_mean(), *w.contact_force(), *rd.external_force])
print(json.dumps(out))
"""


def test_kernels_run_uncompiled_with_the_same_results() -> None:
    """Under NUMBA_DISABLE_JIT=1 the kernels are plain Python: same physics bit for bit (the kernels
    do the same float operations), the observer's force to 1e-9 N."""
    runs = {}
    for jit in ("0", "1"):
        env = {**os.environ, "NUMBA_DISABLE_JIT": jit, "MUJOCO_GL": "egl"}
        res = subprocess.run(
            [sys.executable, "-c", _UNCOMPILED_RUN], env=env, capture_output=True, text=True, timeout=300
        )
        assert res.returncode == 0, res.stderr
        runs[jit] = np.array(json.loads(res.stdout.strip().splitlines()[-1]))
    compiled, plain = runs["0"], runs["1"]
    np.testing.assert_array_equal(compiled[:, :-3], plain[:, :-3])
    np.testing.assert_allclose(compiled[:, -3:], plain[:, -3:], rtol=0, atol=1e-9)
    assert np.max(np.abs(compiled[:, -3:])) > 1.0


def test_a_new_world_starts_as_reset_leaves_it(panda_scene) -> None:
    """The kernels' warm-up tick in the constructor leaves no trace."""
    w = SimWorld(panda_scene)
    assert w.time == 0.0
    np.testing.assert_array_equal(w.q, panda_scene.q0)
    np.testing.assert_array_equal(w.q_ref, panda_scene.q0)
    np.testing.assert_array_equal(w.dq, np.zeros(7))
    assert not np.any(w.data.xfrc_applied) and not np.any(w.data.warning.number)
    np.testing.assert_array_equal(w.joint_torque_tick_mean(), w.joint_torque_measured())
