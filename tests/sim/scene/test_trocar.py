"""lapwrench.sim.scene.trocar: the incision on the elastic wall and the trocar welded to the shaft at
eq (18)'s λ0 L, so the shaft passes through the incision point and a lateral offset stretches the wall."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from lapwrench.sim.scene.build import Scene, build_scene
from lapwrench.sim.scene.config import PhantomConfig, SceneConfig
from lapwrench.sim.scene.names import INCISION_BODY, INCISION_JOINTS, SLEEVE_BODY, TROCAR_BODY, TROCAR_WELD
from lapwrench.sim.world import SimWorld


@pytest.fixture(scope="module")
def stiff() -> Scene:
    """A wall twice as stiff as the default, an eight-segment lip and the RCM at 0.7 of the scope."""
    phantom = PhantomConfig(wall_stiffness=2000.0, wall_damping=40.0, ring_segments=8, trocar_timeconst=0.004)
    return build_scene(SceneConfig(phantom=phantom, rcm_lambda0=0.7))


def test_the_wall_is_two_springs_in_its_plane(stiff: Scene) -> None:
    m = stiff.model
    for name, axis in zip(INCISION_JOINTS, np.eye(3)[:2], strict=True):
        j = m.joint(name)
        assert j.type[0] == mujoco.mjtJoint.mjJNT_SLIDE and j.bodyid[0] == m.body(INCISION_BODY).id
        np.testing.assert_array_equal(m.jnt_axis[j.id], axis)
        assert m.jnt_stiffness[j.id] == 2000.0 and m.dof_damping[m.jnt_dofadr[j.id]] == 40.0


def test_the_weld_holds_the_shaft_at_lambda0_l(stiff: Scene) -> None:
    m = stiff.model
    eq = m.equality(TROCAR_WELD)
    assert eq.type[0] == mujoco.mjtEq.mjEQ_WELD
    assert (m.body(int(eq.obj1id[0])).name, m.body(int(eq.obj2id[0])).name) == (SLEEVE_BODY, "lap_shaft")
    assert eq.data[2] == pytest.approx(0.7 * stiff.config.scope.length)
    assert eq.solref[0] == pytest.approx(0.004)
    assert m.joint("trocar_pivot").type[0] == mujoco.mjtJoint.mjJNT_BALL
    assert m.body(SLEEVE_BODY).parentid[0] == m.body(TROCAR_BODY).id


def test_at_the_start_the_shaft_passes_through_the_unloaded_incision(stiff: Scene) -> None:
    w = SimWorld(stiff)
    try:
        assert w.rcm_error() < 1e-9 and np.linalg.norm(w.contact_force()) < 1e-9
        p_E, d_z = w.shaft_axis()
        np.testing.assert_allclose(stiff.incision_position, p_E + 0.7 * stiff.config.scope.length * d_z, atol=1e-9)
    finally:
        w.close()
