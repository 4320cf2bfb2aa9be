"""lapwrench.sim.scene.names: every name other modules look up exists in the built world, as the kind
of element they look it up as."""

from __future__ import annotations

import mujoco

from lapwrench.sim.scene import names
from lapwrench.sim.scene.build import Scene


def test_every_looked_up_name_is_in_the_compiled_world(panda_scene: Scene) -> None:
    m = panda_scene.model
    kinds = {
        mujoco.mjtObj.mjOBJ_BODY: (names.TROCAR_BODY, names.SLEEVE_BODY, names.HANDLE_BODY, names.HOUSING_BODY,
                                   names.INCISION_BODY, names.NEEDLE_BODY, names.ORGAN_BODY, *names.INSTRUMENT_BODIES,
                                   *names.GAUZE_BODIES),
        mujoco.mjtObj.mjOBJ_JOINT: (*names.INCISION_JOINTS, *names.HOUSING_JOINTS),
        mujoco.mjtObj.mjOBJ_SITE: (*names.PORT_SITES, *names.INSTRUMENT_TIP_SITES),
        mujoco.mjtObj.mjOBJ_SENSOR: (names.FT_FORCE_SENSOR, names.FT_TORQUE_SENSOR),
        mujoco.mjtObj.mjOBJ_CAMERA: (names.CAMERA_NAME, names.OVERVIEW_CAMERA_NAME),
        mujoco.mjtObj.mjOBJ_EQUALITY: (names.TROCAR_WELD,),
    }
    missing = [(kind.name, n) for kind, ns in kinds.items() for n in ns if mujoco.mj_name2id(m, kind, n) < 0]
    assert not missing


def test_the_incision_lips_carry_the_ring_prefix(panda_scene: Scene) -> None:
    m = panda_scene.model
    lips = [m.geom(i).name for i in range(m.ngeom) if m.geom(i).name.startswith(names.RING_GEOM_PREFIX)]
    assert len(lips) == panda_scene.config.phantom.ring_segments
    assert {m.geom(n).bodyid[0] for n in lips} == {m.body(names.INCISION_BODY).id}


def test_paired_names_are_distinct() -> None:
    for pair in (names.INCISION_JOINTS, names.HOUSING_JOINTS, names.PORT_SITES, names.INSTRUMENT_TIP_SITES,
                 names.INSTRUMENT_BODIES, names.GAUZE_BODIES):
        assert len(pair) == 2 and pair[0] != pair[1]
