"""Building SimWorld: per-world gains, cached ids and views, a new world as reset leaves it."""

from __future__ import annotations

import mujoco
import numpy as np

from lapwrench.sim.scene.build import Scene
from lapwrench.sim.world import JointServoGains, SimWorld


def _plain_contact_force(world: SimWorld) -> np.ndarray:
    d = world.data
    weld = world.model.equality("trocar_weld").id
    rows = np.flatnonzero(
        (d.efc_type[: d.nefc] == mujoco.mjtConstraint.mjCNSTR_EQUALITY) & (d.efc_id[: d.nefc] == weld)
    )
    return np.zeros(3) if rows.size < 3 else -d.efc_force[rows[:3]]


def test_worlds_sharing_a_scene_keep_their_own_gains(panda_scene: Scene) -> None:
    soft = JointServoGains(stiffness=(300.0,) * 7, damping=(10.0,) * 7)
    a = SimWorld(panda_scene, gains=soft)
    b = SimWorld(panda_scene)
    assert a.model.actuator_gainprm[0, 0] == 300.0 and b.model.actuator_gainprm[0, 0] == 3000.0


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


def test_a_new_world_starts_as_reset_leaves_it(panda_scene: Scene) -> None:
    """The kernels' warm-up tick in the constructor leaves no trace."""
    w = SimWorld(panda_scene)
    assert w.time == 0.0
    np.testing.assert_array_equal(w.q, panda_scene.q0)
    np.testing.assert_array_equal(w.q_ref, panda_scene.q0)
    np.testing.assert_array_equal(w.dq, np.zeros(7))
    assert not np.any(w.data.xfrc_applied) and not np.any(w.data.warning.number)
    np.testing.assert_array_equal(w.joint_torque_tick_mean(), w.joint_torque_measured())
