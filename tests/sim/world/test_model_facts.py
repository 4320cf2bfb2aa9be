"""Facts about the compiled model: whether the mocap bodies are inert."""

from __future__ import annotations

import mujoco

from lapwrench.sim.world import SimWorld
from lapwrench.sim.world.model_facts import mocap_is_inert


def test_mocap_inertness() -> None:
    assert mocap_is_inert(SimWorld().model)  # the instruments only show
    base = """<mujoco><worldbody>
      <body name="a" mocap="true"><geom size=".01" {geom}/><site name="s"/></body>
      <body name="b"><freejoint/><geom size=".01" contype="0" conaffinity="0"/></body>
      </worldbody>{extra}</mujoco>"""
    inert = base.format(geom='contype="0" conaffinity="0"', extra="")
    assert mocap_is_inert(mujoco.MjModel.from_xml_string(inert))
    touching = base.format(geom="", extra="")
    assert not mocap_is_inert(mujoco.MjModel.from_xml_string(touching))
    welded = base.format(geom='contype="0" conaffinity="0"', extra='<equality><weld body1="a" body2="b"/></equality>')
    assert not mocap_is_inert(mujoco.MjModel.from_xml_string(welded))
    pulled = base.format(
        geom='contype="0" conaffinity="0"',
        extra='<actuator><general site="s" refsite="s"/></actuator>',
    )
    assert not mocap_is_inert(mujoco.MjModel.from_xml_string(pulled))
