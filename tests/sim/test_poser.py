"""The scope poser: IK poses that keep the shaft through the incision."""

from __future__ import annotations

import numpy as np

from lapwrench.sim.poser import ScopePoser
from lapwrench.sim.world import SimWorld


def test_scope_poses_keep_the_shaft_through_the_incision(world: SimWorld) -> None:
    poser = ScopePoser(world)
    q = poser.configuration(0.15, -0.1, 0.5, -0.02)
    assert q is not None
    world.reset(q)
    try:
        assert world.rcm_error() < 1e-3
        p_c, _ = world.frame_pose("lap_C")
        world.reset(poser.q0)
        p0, _ = world.frame_pose("lap_C")
        assert np.linalg.norm(p_c - p0) > 0.01  # the camera did move
    finally:
        world.reset()
