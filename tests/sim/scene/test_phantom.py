"""lapwrench.sim.scene.phantom: the abdominal phantom on its table: a housing on two springs at the
incision, the body wall with holes at the incision and the ports, the tissue, organ, needle and gauze."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from lapwrench.sim.scene.build import Scene, build_scene
from lapwrench.sim.scene.config import PhantomConfig, SceneConfig
from lapwrench.sim.scene.names import GAUZE_BODIES, HOUSING_BODY, HOUSING_JOINTS, NEEDLE_BODY, ORGAN_BODY, PORT_SITES

PORTS = ((0.04, 0.08), (0.02, -0.1))


@pytest.fixture(scope="module")
def scene() -> Scene:
    return build_scene(SceneConfig(phantom=PhantomConfig(housing_stiffness=3500.0, port_offsets=PORTS)))


def test_the_housing_sits_at_the_incision_on_two_horizontal_springs(scene: Scene) -> None:
    m = scene.model
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    np.testing.assert_allclose(d.xpos[m.body(HOUSING_BODY).id], scene.incision_position, atol=1e-12)
    for name, axis in zip(HOUSING_JOINTS, np.eye(3)[:2], strict=True):
        j = m.joint(name).id
        assert m.jnt_type[j] == mujoco.mjtJoint.mjJNT_SLIDE and m.jnt_stiffness[j] == 3500.0
        np.testing.assert_array_equal(m.jnt_axis[j], axis)
    assert m.body_mass[m.body(HOUSING_BODY).id] == pytest.approx(3.0)


def test_the_ports_are_where_the_config_puts_them(scene: Scene) -> None:
    m = scene.model
    for site, (px, py) in zip(PORT_SITES, PORTS, strict=True):
        np.testing.assert_allclose(m.site_pos[m.site(site).id], [px, py, 0.0])
        assert m.site_bodyid[m.site(site).id] == m.body(HOUSING_BODY).id


def test_the_body_wall_has_holes_at_the_incision_and_the_ports(scene: Scene) -> None:
    m = scene.model
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    mesh, geom = m.mesh("body_wall").id, m.geom("body_wall").id
    v0, nv = m.mesh_vertadr[mesh], m.mesh_vertnum[mesh]
    f0, nf = m.mesh_faceadr[mesh], m.mesh_facenum[mesh]
    # the compiler moves a mesh to its inertial frame and the geom's pose undoes it: world coordinates
    verts = d.geom_xpos[geom] + m.mesh_vert[v0 : v0 + nv] @ d.geom_xmat[geom].reshape(3, 3).T
    centres = verts[m.mesh_face[f0 : f0 + nf]].mean(axis=1)[:, :2] - scene.incision_position[:2]
    for (hx, hy), r in (((0.0, 0.0), 0.012), (PORTS[0], 0.01), (PORTS[1], 0.01), ((0.1, 0.0), 0.0)):
        dist = np.hypot(centres[:, 0] - hx, centres[:, 1] - hy).min()
        # no face over a hole; elsewhere the slab's triangles (1 cm cells) come within 5 mm of any point
        assert dist > 0.6 * r if r else dist < 0.005, (hx, hy, dist)
    assert nf > 1000


def test_the_scene_dressing_is_on_the_tissue(scene: Scene) -> None:
    m = scene.model
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    floor_z = scene.incision_position[2] - PhantomConfig().tissue_depth
    for body in (ORGAN_BODY, NEEDLE_BODY, *GAUZE_BODIES):
        assert d.xpos[m.body(body).id][2] == pytest.approx(floor_z, abs=2e-3), body
        assert m.body(body).parentid[0] == m.body(HOUSING_BODY).id
