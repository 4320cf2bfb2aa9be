"""Loads and props: instruments through their ports, the housing load for a shift, the hand wrench."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.sim.world import SimWorld


def _run(world: SimWorld, q_ref: np.ndarray, n: int) -> None:
    for _ in range(n):
        world.step(q_ref)


def test_instruments_pass_through_ports(world: SimWorld) -> None:
    tip = world.incision_position() + np.array([0.01, 0.02, -0.12])
    world.set_instrument_tip(0, tip)
    world.step(world.scene.q0)
    np.testing.assert_allclose(world.instrument_tip(0), tip)
    port = world.port_position(0)
    R = world.data.xmat[world.model.body("instrument_left").id].reshape(3, 3)
    axis = R[:, 2]
    r = port - tip
    assert np.linalg.norm(r - (r @ axis) * axis) < 1e-9, "shaft axis passes through the port"
    assert (tip - port) @ axis > 0.1
    _uv, z = world.project_to_image(tip)
    assert z > 0
    assert world.n_instruments == 2  # the paper's two instruments, each through its own port
    assert np.linalg.norm(world.port_position(1) - port) > 0.05


def test_housing_load_for_a_10mm_shift(world: SimWorld) -> None:
    """Fig. 5 disturbance: the helper's load shifts the housing ~10 mm with the scope holding."""
    load = world.housing_load_for_shift(np.array([0.0, 0.01]))
    world.set_housing_load(load)
    _run(world, world.scene.q0, 1500)
    assert world.housing_displacement()[1] == pytest.approx(0.01, abs=0.0015)
    assert 5.0 < np.linalg.norm(world.contact_force()) < 12.0


def test_the_hand_wrench_is_applied_as_given_and_refused_by_name(world: SimWorld) -> None:
    world.set_hand_wrench(force=np.array([1.5, -2.0, 0.25]), torque=[0.0, -0.0, 1e-3])
    assert np.array_equal(world.hand_force(), [1.5, -2.0, 0.25])
    assert np.array_equal(world.hand_torque(), [0.0, -0.0, 1e-3])
    world.set_hand_wrench(torque=(1, 2, 3))  # integers are numbers; the omitted force is zero
    assert np.array_equal(world.hand_force(), np.zeros(3)) and np.array_equal(world.hand_torque(), [1.0, 2.0, 3.0])
    for kwargs, name in [({"force": [1.0, 2.0]}, "force"), ({"torque": [0.0, np.inf, 0.0]}, "torque"),
                         ({"force": [[1.0, 2.0, 3.0]]}, "force")]:
        with pytest.raises(ValueError, match=f"hand {name} must be 3 finite numbers"):
            world.set_hand_wrench(**kwargs)
    assert np.array_equal(world.hand_torque(), [1.0, 2.0, 3.0])  # a refused wrench leaves the last one
    world.set_hand_wrench()
    assert not world.hand_force().any() and not world.hand_torque().any()
