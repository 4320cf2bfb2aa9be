"""Simulated sensors: what each one measures, with its noise, bias and rate."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from lapwrench.robot.model import RobotModel
from lapwrench.sim.robot import ForceEstimateConfig, SimRobot
from lapwrench.sim.sensors import (
    ExternalForceObserver,
    ForceTorqueNoise,
    GripModel,
    SimForceTorqueSensor,
    TactileGripModel,
)
from lapwrench.sim.world import SimWorld
from lapwrench.wrenches.interaction import grip_gain


@pytest.fixture(scope="module")
def world() -> SimWorld:
    return SimWorld()


def _hold(world: SimWorld, ticks: int) -> None:
    for _ in range(ticks):
        world.step(world.scene.q0)


def test_ft_sensor_measures_only_the_hand(world: SimWorld) -> None:
    world.reset()
    world.set_housing_load(world.housing_load_for_shift(np.array([0.0, 0.01])))  # trocar pushes the scope
    ft = SimForceTorqueSensor(world, ForceTorqueNoise(force_sigma=0.0, torque_sigma=0.0))
    _hold(world, 300)
    ft.tare()
    assert np.linalg.norm(world.contact_force()) > 5.0
    hand = np.array([3.0, -2.0, 1.0, 0.05, -0.02, 0.1])
    world.set_hand_wrench(hand)
    _hold(world, 50)
    r = ft.read(1.0)
    _, R_H = world.frame_pose("lap_H")
    np.testing.assert_allclose(R_H @ r.force, hand[:3], atol=1e-6)
    np.testing.assert_allclose(R_H @ r.torque, hand[3:], atol=1e-6)
    world.set_hand_wrench(np.zeros(6))
    world.set_housing_load(np.zeros(3))


def test_ft_noise_bias_and_rate(world: SimWorld) -> None:
    world.reset()
    ft = SimForceTorqueSensor(world, ForceTorqueNoise(rate_hz=100.0, force_sigma=0.2), seed=1)
    raw = [ft.read(k * 1e-3).force.copy() for k in range(1000)]
    changes = sum(1 for a, b in itertools.pairwise(raw) if not np.array_equal(a, b))
    assert 95 <= changes <= 101  # a new sample every 10 ms, held in between
    samples = np.array(raw[::10])
    assert np.std(samples[:, 0]) == pytest.approx(0.2, rel=0.3)
    assert np.mean(samples[:, 0]) == pytest.approx(0.2, abs=0.1)  # the untared bias
    with pytest.raises(ValueError, match="rate_hz"):
        SimForceTorqueSensor(world, ForceTorqueNoise(rate_hz=0.0))


@pytest.mark.parametrize(("grip", "delta"), [(30.0, 2.0), (17.0, 1.1), (5.0, 0.3)])
def test_grip_model_gives_the_paper_grip_levels(grip: float, delta: float) -> None:
    tactile = TactileGripModel(seed=0)
    values = np.array([tactile.values(grip) for _ in range(50)])
    assert values.shape == (50, 64)
    assert values.min() >= 0 and values.max() <= 255 and np.all(values == np.round(values))
    d = np.mean([grip_gain(v, 2000.0, 3)[0] for v in values])
    assert d == pytest.approx(delta, abs=0.1)


def test_light_touch_does_not_engage_the_handle() -> None:
    tactile = TactileGripModel(GripModel(patch_per_sqrt_newton=3.0), seed=0)
    assert grip_gain(tactile.values(0.5), 2000.0, 3) == (0.0, pytest.approx(2, abs=1))
    assert not np.any(tactile.values(0.0))


def test_force_estimate_includes_the_trocar_and_carries_torque_sensor_errors(world: SimWorld) -> None:
    world.reset()
    world.set_housing_load(world.housing_load_for_shift(np.array([0.01, 0.0])))
    clean = SimRobot(world)
    r = clean.connect()
    for _ in range(600):
        clean.command(world.scene.q0)
        r = clean.read()
    truth = world.contact_force() + world.hand_wrench()[:3]
    assert np.linalg.norm(truth) > 5.0
    np.testing.assert_allclose(r.external_force, truth, atol=0.3)
    noisy = SimRobot(world, estimate=ForceEstimateConfig(torque_noise=0.05, torque_bias=0.2, seed=2))
    noisy.connect()
    for _ in range(300):
        noisy.command(world.scene.q0)
        r2 = noisy.read()
    assert 0.05 < np.linalg.norm(r2.external_force - truth) < 5.0
    world.set_housing_load(np.zeros(3))


def test_observer_rejects_a_bad_gain() -> None:
    with pytest.raises(ValueError, match="gain"):
        ExternalForceObserver(RobotModel("panda"), gain=0.0)
