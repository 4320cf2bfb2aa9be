"""Simulated sensors: what each one measures, with its noise, bias and rate."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from lapwrench.config import Config
from lapwrench.robot.model import RobotModel
from lapwrench.sim.robot import ForceEstimateConfig, SimRobot
from lapwrench.sim.scene.build import build_scene
from lapwrench.sim.scene.config import SceneConfig
from lapwrench.sim.sensors import (
    NOISE_BLOCK_SAMPLES,
    ExternalForceObserver,
    ForceTorqueNoise,
    GripModel,
    SimForceTorqueSensor,
    TactileGripModel,
)
from lapwrench.sim.world import SimWorld
from lapwrench.wrenches.grip_weight import grip_weight_change
from lapwrench.wrenches.interaction import grip_gain


@pytest.fixture(scope="module")
def world() -> SimWorld:
    return SimWorld()


def _hold(world: SimWorld, ticks: int) -> None:
    for _ in range(ticks):
        world.step(world.scene.q0)


def test_ft_sensor_measures_the_hand_and_the_grips_weight(world: SimWorld) -> None:
    """The trocar's push never reaches the handle sensor; the hand's wrench does, and so does what the
    grip's weight adds as the scope turns from where the sensor was tared (lapwrench.wrenches.grip_weight)."""
    world.reset()
    world.set_housing_load(world.housing_load_for_shift(np.array([0.0, 0.01])))  # trocar pushes the scope
    ft = SimForceTorqueSensor(world, ForceTorqueNoise(force_sigma=0.0, torque_sigma=0.0))
    _hold(world, 300)
    ft.tare()
    _, R_H0 = world.frame_pose("lap_H")
    assert np.linalg.norm(world.contact_force()) > 5.0
    force, torque = np.array([3.0, -2.0, 1.0]), np.array([0.05, -0.02, 0.1])
    world.set_hand_wrench(force=force, torque=torque)
    _hold(world, 50)
    r = ft.read(1.0)
    _, R_H = world.frame_pose("lap_H")
    scope = world.scene.config.scope
    assert scope.grip_mass > 0.0
    dF, dT = grip_weight_change(R_H, R_H0, scope.grip_mass, np.array(scope.grip_com))
    assert np.linalg.norm(dF) > 1e-4  # the scope turned: the weight's share changed
    # what is left is the grip's inertia, m a: 6 mN here, as the push accelerates the arm
    np.testing.assert_allclose(R_H @ (r.force - dF), force, atol=1e-2)
    np.testing.assert_allclose(R_H @ (r.torque - dT), torque, atol=1e-3)
    world.set_hand_wrench()
    world.set_housing_load(np.zeros(3))


def test_ft_sensor_reads_the_grips_weight_at_rest() -> None:
    """Untared and untouched, the sensor reads m R_Hᵀ g and c x (m R_Hᵀ g); a grip of mass 0 reads nothing."""
    for mass in (0.1, 0.0):
        cfg = Config().replace(scope={"grip_mass": mass, "grip_com": [0.01, -0.02, 0.03]})
        w = SimWorld(build_scene(SceneConfig.from_config(cfg)))
        ft = SimForceTorqueSensor(w, ForceTorqueNoise(force_sigma=0.0, torque_sigma=0.0, force_bias=(0.0, 0.0, 0.0),
                                                      torque_bias=(0.0, 0.0, 0.0)))
        _hold(w, 20)
        _, R_H = w.frame_pose("lap_H")
        r = ft.read(0.0)
        weight = mass * R_H.T @ np.array([0.0, 0.0, -9.81])
        np.testing.assert_allclose(r.force, weight, atol=1e-4)
        np.testing.assert_allclose(r.torque, np.cross([0.01, -0.02, 0.03], weight), atol=1e-5)
        w.close()


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
    truth = world.contact_force() + world.hand_force()
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


def test_compiled_observer_matches_the_numpy_one() -> None:
    """The observer's compiled tick (one kernel around the Pinocchio calls) against the same tick in
    numpy, on random states and torques over many ticks: force and residual to 1e-9."""
    model = RobotModel("panda")
    fast, ref = ExternalForceObserver(model), ExternalForceObserver(model)
    rng = np.random.default_rng(11)
    q = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8])
    for k in range(300):
        if k % 100 == 0:
            fast.reset()
            ref.reset()
            q = q + rng.normal(0.0, 0.3, 7)
        dq = rng.normal(0.0, 0.8, 7)
        q = q + dq * 1e-3
        tau = rng.normal(0.0, 20.0, 7)
        f = fast.update(q, dq, tau, 1e-3)
        f_ref = ref.update_reference(q, dq, tau, 1e-3)
        np.testing.assert_allclose(f, f_ref, rtol=0, atol=1e-9 * max(1.0, np.abs(f_ref).max()))
        np.testing.assert_allclose(fast.r, ref.r, rtol=0, atol=1e-9 * max(1.0, np.abs(ref.r).max()))
    assert np.abs(f_ref).max() > 1.0
    # lists and views are accepted like arrays
    np.testing.assert_allclose(fast.update(list(q), dq[::-1][::-1], tau, 1e-3), ref.update_reference(q, dq, tau, 1e-3))


def test_ft_reading_is_the_documented_formula(world: SimWorld) -> None:
    """Six cached sensordata addresses and normals drawn ahead in blocks: the same values, bit for bit,
    as the sensors' force and torque read by name with a draw of three per part and sample, across
    the end of a block."""
    world.reset()
    world.set_hand_wrench(force=[3.0, -2.0, 1.0], torque=[0.05, -0.02, 0.1])
    _hold(world, 20)
    noise = ForceTorqueNoise()
    ft = SimForceTorqueSensor(world, noise, seed=5)
    rng = np.random.default_rng(5)
    m, d = world.model, world.data
    for k in range(NOISE_BLOCK_SAMPLES + 5):
        fa, ma = m.sensor("handle_ft_force").adr[0], m.sensor("handle_ft_torque").adr[0]
        expected = -np.concatenate([d.sensordata[fa : fa + 3], d.sensordata[ma : ma + 3]])
        expected[:3] += np.asarray(noise.force_bias) + noise.force_sigma * rng.standard_normal(3)
        expected[3:] += np.asarray(noise.torque_bias) + noise.torque_sigma * rng.standard_normal(3)
        reading = ft.read(k / noise.rate_hz)  # one new sample per period (untared: x - 0.0 == x)
        np.testing.assert_array_equal(np.concatenate([reading.force, reading.torque]), expected)
        _hold(world, 1)
    world.set_hand_wrench()


def test_tactile_values_are_the_documented_formula() -> None:
    """Patch size, pressure, noise, rounding and the 1-255 clip, bit for bit against the formula."""
    model = GripModel()
    tactile = TactileGripModel(model, seed=8)
    rng = np.random.default_rng(8)
    order = rng.permutation(64)
    for grip in (0.0, 0.004, 0.3, 5.0, 17.0, 30.0, 200.0):
        expected = np.zeros(64)
        n_c = int(min(64, round(model.patch_per_sqrt_newton * np.sqrt(grip)))) if grip > 0 else 0
        if n_c:
            vals = model.counts_per_newton * grip / n_c + model.element_sigma * rng.standard_normal(n_c)
            expected[order[:n_c]] = np.clip(np.round(vals), 1.0, 255.0)
        np.testing.assert_array_equal(tactile.values(grip), expected)
