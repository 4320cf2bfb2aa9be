"""The MuJoCo scene and the controller's Pinocchio model come from the same URDF and must agree."""

from __future__ import annotations

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from lapwrench.robot.description import ARM_SPECS, FRAME_E, build_urdf
from lapwrench.sim.scene.arm import build_arm_spec
from lapwrench.sim.scene.build import build_scene
from lapwrench.sim.scene.config import SceneConfig


def _full_mass_matrix(m: mujoco.MjModel, d: mujoco.MjData) -> np.ndarray:
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    return M


@pytest.mark.parametrize("kind", ["panda", "fr3"])
@pytest.mark.parametrize("armature", [0.0, 0.1])
def test_mass_matrix_and_flange_jacobian_agree(kind: str, armature: float) -> None:
    pmodel = pin.buildModelFromXML(build_urdf(kind))
    pdata = pmodel.createData()
    fid = pmodel.getFrameId(FRAME_E)
    names = ARM_SPECS[kind].joint_names
    pin_idx = np.array([pmodel.joints[pmodel.getJointId(n)].idx_v for n in names])

    m = build_arm_spec(kind, armature=armature).compile()
    d = mujoco.MjData(m)
    qadr = np.array([m.joint(n).qposadr[0] for n in names])
    vadr = np.array([m.joint(n).dofadr[0] for n in names])
    assert m.nv == 7 and pmodel.nv == 7
    body = m.body(FRAME_E).id
    lo, hi = m.jnt_range[:, 0], m.jnt_range[:, 1]

    rng = np.random.default_rng(42)
    for _ in range(6):
        q = rng.uniform(lo + 0.05, hi - 0.05)
        d.qpos[qadr] = q
        mujoco.mj_forward(m, d)
        M_mj = _full_mass_matrix(m, d)[np.ix_(vadr, vadr)] - armature * np.eye(7)

        qp = np.zeros(pmodel.nq)
        qp[pin_idx] = q
        M_pin = pin.crba(pmodel, pdata, qp)
        M_pin = np.triu(M_pin) + np.triu(M_pin, 1).T
        M_pin = M_pin[np.ix_(pin_idx, pin_idx)]
        np.testing.assert_allclose(M_mj, M_pin, atol=1e-8, rtol=1e-6)

        jp = np.zeros((3, m.nv))
        jr = np.zeros((3, m.nv))
        mujoco.mj_jacBody(m, d, jp, jr, body)
        J_mj = np.vstack([jp, jr])[:, vadr]
        pin.computeJointJacobians(pmodel, pdata, qp)
        pin.updateFramePlacements(pmodel, pdata)
        J_pin = pin.getFrameJacobian(pmodel, pdata, fid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[:, pin_idx]
        np.testing.assert_allclose(J_mj, J_pin, atol=1e-9)
        np.testing.assert_allclose(d.xpos[body], pdata.oMf[fid].translation, atol=1e-9)
        np.testing.assert_allclose(d.xmat[body].reshape(3, 3), pdata.oMf[fid].rotation, atol=1e-9)


def test_scene_arm_matches_arm_spec_up_to_armature() -> None:
    """The full world adds no mass to the arm: its arm mass matrix is the bare arm's plus armature."""
    cfg = SceneConfig(kind="fr3")
    scene = build_scene(cfg)
    m = scene.model
    d = mujoco.MjData(m)
    d.qpos[scene.arm_qpos_adr] = scene.q0
    mujoco.mj_forward(m, d)
    M = _full_mass_matrix(m, d)[np.ix_(scene.arm_dof_adr, scene.arm_dof_adr)]

    m0 = build_arm_spec("fr3").compile()
    d0 = mujoco.MjData(m0)
    d0.qpos[:] = scene.q0
    mujoco.mj_forward(m0, d0)
    np.testing.assert_allclose(M - cfg.armature * np.eye(7), _full_mass_matrix(m0, d0), atol=1e-10)
