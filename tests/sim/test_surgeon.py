"""The scripted surgeon: the speed-driven hand is capped, rate-limited and lets go."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.sim.surgeon import SpeedDrivenHand
from lapwrench.sim.world import SimWorld


def test_speed_driven_hand_is_capped_and_rate_limited(world: SimWorld) -> None:
    _, R_E = world.frame_pose("lap_E")
    hand = SpeedDrivenHand(R_E[:, 0], speed=1.0, grip_force=30.0)
    forces = []
    for k in range(100):  # the world is not stepped: the shaft does not move, the hand pushes harder
        assert hand.apply(world, k * 1e-3, 1e-3) == 30.0
        forces.append(np.linalg.norm(world.hand_force()))
    assert forces[0] == pytest.approx(0.6)  # 600 N/s
    assert max(forces) == pytest.approx(30.0)
    _, d = world.shaft_axis()
    assert abs(world.hand_force() @ d) < 1e-9  # perpendicular to the shaft
    hand.engaged = False
    grips = [hand.apply(world, 0.1 + k * 1e-3, 1e-3) for k in range(60)]
    assert grips[0] == 30.0 and grips[-1] == 0.0  # lets the push fall, then lets go
