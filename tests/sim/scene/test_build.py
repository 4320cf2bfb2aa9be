"""The built scene: default pose into the incision, nothing colliding."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.sim.scene.arm import default_initial_configuration
from lapwrench.sim.scene.build import build_scene
from lapwrench.sim.scene.config import SceneConfig
from lapwrench.sim.scene.names import INSTRUMENT_BODIES
from lapwrench.sim.world import SimWorld


@pytest.mark.parametrize("kind", ["panda", "fr3"])
def test_default_pose_points_into_incision(kind: str) -> None:
    scene = build_scene(SceneConfig(kind=kind))
    m = scene.model
    q0 = default_initial_configuration(kind)
    np.testing.assert_array_equal(scene.q0, q0)
    lo = m.jnt_range[[m.joint(n).id for n in scene.arm_joint_names], 0]
    hi = m.jnt_range[[m.joint(n).id for n in scene.arm_joint_names], 1]
    assert np.all(q0 - lo > 0.5) and np.all(hi - q0 > 0.5), "q0 must sit well inside the joint limits"
    w = SimWorld(scene)
    p_e, d_z = w.shaft_axis()
    assert d_z[2] < -0.99, "the scope points down into the abdomen"
    np.testing.assert_allclose(scene.incision_position, p_e + 0.8 * 0.29 * d_z, atol=1e-9)
    np.testing.assert_allclose(w.incision_position(), scene.incision_position, atol=1e-9)
    assert w.rcm_error() < 1e-9
    assert w.insertion_depth() == pytest.approx(0.232, abs=1e-9)
    assert np.linalg.norm(w.contact_force()) < 1e-9
    # Nothing collides; the trocar weld is the only robot-phantom interaction.
    assert m.npair == 0 and m.neq == 1
    assert np.all(m.geom_contype == 0) and np.all(m.geom_conaffinity == 0)
    for b in INSTRUMENT_BODIES:
        assert m.body_mocapid[m.body(b).id] >= 0
