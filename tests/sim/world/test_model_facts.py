"""Facts about the compiled model: whether the mocap bodies are inert, whether contacts can arise."""

from __future__ import annotations

import mujoco

from lapwrench.sim.world import SimWorld
from lapwrench.sim.world.model_facts import contacts_impossible, mocap_is_inert


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


def test_contacts_are_impossible_only_without_pairs_and_without_meeting_bits() -> None:
    assert contacts_impossible(SimWorld().model)  # nothing in the scene collides: the world skips the pass
    base = """<mujoco><worldbody>
      <body><freejoint/><geom size=".01" contype="{a}" conaffinity="{b}"/></body>
      <body><freejoint/><geom name="g" size=".01" contype="{c}" conaffinity="{d}"/></body>
      </worldbody>{extra}</mujoco>"""

    def impossible(a: int, b: int, c: int, d: int, extra: str = "") -> bool:
        return contacts_impossible(mujoco.MjModel.from_xml_string(base.format(a=a, b=b, c=c, d=d, extra=extra)))

    assert impossible(0, 0, 0, 0)
    assert impossible(1, 0, 1, 0)  # types without affinity meet nothing
    assert not impossible(1, 0, 0, 1)  # one's type meets the other's affinity
    assert not impossible(0, 0, 0, 0, '<contact><pair geom1="g" geom2="g"/></contact>')  # an explicit pair
