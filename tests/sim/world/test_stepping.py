"""The SimWorld tick: servo tracking, timing, instability detection, bad references."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from lapwrench.sim.scene.build import Scene
from lapwrench.sim.scene.config import SceneConfig
from lapwrench.sim.world import SimulationUnstableError, SimWorld


def _run(world: SimWorld, q_ref: np.ndarray, n: int) -> None:
    for _ in range(n):
        world.step(q_ref)


def test_timing(world: SimWorld) -> None:
    assert world.timestep == pytest.approx(0.0005)
    assert world.n_substeps == 2
    world.step(world.scene.q0)
    assert world.time == pytest.approx(0.001)


def test_static_reference_is_held(world: SimWorld) -> None:
    q_ref = world.scene.q0 + np.array([0.01, -0.01, 0.01, 0.01, -0.02, 0.01, 0.3])
    world.reset(q_ref)
    assert world.rcm_error() < 1e-9, "reset puts the trocar on the shaft axis"
    f0 = np.linalg.norm(world.contact_force())
    assert 1.0 < f0 < 15.0, "the shaft starts off the unloaded incision: the wall pushes"
    _run(world, q_ref, 500)
    assert np.max(np.abs(world.q - q_ref)) < 2e-3
    assert np.max(np.abs(world.dq)) < 1e-2
    tau = world.motor_torque()
    assert np.all(np.abs(tau) <= np.array([87.0] * 4 + [12.0] * 3) + 1e-9)


def test_slow_sinusoid_is_followed(world: SimWorld) -> None:
    """0.5 Hz motion; the error includes the wall's push (the shaft moves ~1 cm at the incision)."""
    q0 = world.scene.q0
    amp = np.array([0.02, 0.02, 0.02, 0.03, 0.05, 0.03, 0.1])
    errs = []
    for _ in range(1500):
        t = world.time + 0.001
        world.step(q0 + amp * np.sin(2 * np.pi * 0.5 * t))
        if t > 0.3:
            errs.append(np.abs(world.q - world.q_ref))
    assert np.max(errs) < 5e-3
    assert np.max(np.abs(np.array(errs)[:, 6])) < 1e-3  # roll about the shaft: no wall load


def test_hand_push_and_disturbance_stay_stable_fr3() -> None:
    """FR3 (light link 7): 2 s of hand push plus a 10 mm housing shift, no blow-up."""
    w = SimWorld(SceneConfig(kind="fr3"))
    q0 = w.scene.q0
    peak = 0.0
    for i in range(2000):
        if i == 200:
            w.set_hand_wrench(force=[0.0, 8.0, 0.0], torque=[0.0, 0.0, 0.3])
        if i == 800:
            w.set_housing_load(np.array([35.0, 0.0, 0.0]))
        w.step(q0)
        peak = max(peak, float(np.linalg.norm(w.contact_force())))
    assert np.all(np.isfinite(w.q))
    assert 5.0 < peak < 60.0
    assert np.linalg.norm(w.housing_displacement()) > 0.008


def test_instability_detector_fires_on_nan(world: SimWorld) -> None:
    world.step(world.scene.q0)
    world.data.qvel[world.scene.arm_dof_adr[3]] = np.nan
    with pytest.raises(SimulationUnstableError, match=r"t = 0\.0010 s.*qpos/qvel") as info:
        world.step(world.scene.q0)
    assert info.value.time == pytest.approx(0.001)


def test_instability_detector_fires_on_mujoco_divergence(world: SimWorld) -> None:
    world.step(world.scene.q0)
    world.data.qvel[world.scene.arm_dof_adr[0]] = 1e12  # MuJoCo resets on |qvel| > 1e10 and warns
    with pytest.raises(SimulationUnstableError, match="MuJoCo state"):
        world.step(world.scene.q0)


def test_instability_detector_fires_on_contact_blowup(panda_scene: Scene) -> None:
    w = SimWorld(panda_scene, max_contact_force=3.0)
    w.set_housing_load(np.array([0.0, 40.0, 0.0]))
    with pytest.raises(SimulationUnstableError, match="contact force") as info:
        for _ in range(2000):
            w.step(w.scene.q0)
    assert info.value.quantity.startswith("shaft-incision contact force")
    assert 0.0 < info.value.time < 2.0


def test_bad_inputs_raise(world: SimWorld) -> None:
    with pytest.raises(SimulationUnstableError, match="q_ref"):
        world.step(np.full(7, np.nan))
    with pytest.raises(ValueError, match="hand force"):
        world.set_hand_wrench(force=np.zeros(5))
    with pytest.raises(ValueError, match="hand torque"):
        world.set_hand_wrench(force=np.zeros(3), torque=[0.0, np.nan, 0.0])
    with pytest.raises(TypeError):
        world.set_hand_wrench(np.zeros(6))  # type: ignore[misc]  # no unnamed 6-vector: force and torque by name
    with pytest.raises(ValueError, match="housing load"):
        world.set_housing_load(np.array([np.inf, 0.0, 0.0]))


def test_scope_beyond_the_trocar_is_reported(world: SimWorld) -> None:
    """A pose whose shaft would end above the incision is outside the trocar model: a clear error."""
    world.reset(world.scene.q0 + np.array([0.0, 0.1, 0.0, 0.25, 0.0, 0.15, 0.0]))
    assert world.insertion_depth() > world.scene.config.scope.length
    with pytest.raises(SimulationUnstableError, match=r"insertion depth"):
        world.step(world.q)


# ---------------------------------------------------------------------------------------------
# The compiled tick against the straightforward one


def test_first_substep_reuses_the_closing_forward_only_when_the_state_is_unchanged(
    world: SimWorld, monkeypatch: pytest.MonkeyPatch
) -> None:
    calls = {"mj_step2": 0}
    real = mujoco.mj_step2

    def counting(m: mujoco.MjModel, d: mujoco.MjData) -> None:
        calls["mj_step2"] += 1
        real(m, d)

    monkeypatch.setattr(mujoco, "mj_step2", counting)
    q0 = world.scene.q0
    for _ in range(5):
        world.step(q0)
    assert calls["mj_step2"] == 5
    world.set_instrument_tip(0, world.port_position(0) + np.array([0.0, 0.02, -0.1]))  # inert mocap
    world.set_hand_wrench(force=[1.0, 0.0, 0.0])  # acts in mj_step2 anyway
    world.step(q0)
    assert calls["mj_step2"] == 6
    world.data.qvel[world.scene.arm_dof_adr[2]] += 1e-3  # the caller moved the state: full mj_step
    world.step(q0)
    assert calls["mj_step2"] == 6
    world.step(q0)
    assert calls["mj_step2"] == 7
    world.data.eq_active[0] = 0  # constraint switched off
    world.step(q0)
    assert calls["mj_step2"] == 7
    world.data.eq_active[0] = 1
    world.reset()
    world.step(q0)
    assert calls["mj_step2"] == 8


def test_bad_velocity_references_raise(world: SimWorld) -> None:
    q0 = world.scene.q0
    with pytest.raises(SimulationUnstableError, match="dq_ref"):
        world.step(q0, np.array([0.0, np.inf, 0, 0, 0, 0, 0]))
    with pytest.raises(SimulationUnstableError, match="dq_ref"):
        world.step(q0, np.zeros(6))
    with pytest.raises(SimulationUnstableError, match="q_ref"):
        world.step(np.zeros(6))
    with pytest.raises(SimulationUnstableError, match="q_ref"):
        world.step(np.full(7, np.nan), np.zeros(6))
    assert world.time == 0.0
    world.step(q0[::-1][::-1], np.zeros(7)[::2].repeat(2)[:7])  # non-contiguous views are fine
    assert world.time == pytest.approx(0.001)
    frozen = q0.copy()
    frozen.flags.writeable = False
    world.step(frozen, np.zeros((2, 7))[1])  # so are read-only arrays, lists and other dtypes
    world.step([float(x) for x in q0], np.zeros(7, dtype=np.float32))
    np.testing.assert_array_equal(world.q_ref, q0)
    assert world.time == pytest.approx(0.003)


def _sinusoid_run(world: SimWorld, n: int) -> list[np.ndarray]:
    """``n`` ticks with a moving reference and hand; per tick the state, the sensors and the trocar force."""
    out = []
    q0 = world.scene.q0
    for k in range(n):
        world.set_hand_wrench(force=[3.0 * np.sin(0.01 * k), 1.0, 0.0])
        world.step(q0 + 0.02 * np.sin(2 * np.pi * 0.5 * k * 1e-3))
        out.append(np.concatenate([world.data.qpos, world.data.qvel, world.data.sensordata, world.contact_force()]))
    return out


def test_the_readings_after_a_tick_are_those_of_its_end_state(world: SimWorld) -> None:
    """The sensors are off during the substeps: after the tick they are those of a full forward
    evaluation at its end state, bit for bit, and the model's flags are as they were."""
    flags = world.model.opt.disableflags
    _sinusoid_run(world, 30)
    assert world.model.opt.disableflags == flags
    data = mujoco.MjData(world.model)
    data.qpos[:], data.qvel[:], data.ctrl[:] = world.data.qpos, world.data.qvel, world.data.ctrl
    data.xfrc_applied[:], data.eq_active[:] = world.data.xfrc_applied, world.data.eq_active
    data.mocap_pos[:], data.mocap_quat[:] = world.data.mocap_pos, world.data.mocap_quat
    data.qacc_warmstart[:] = world.data.qacc_warmstart  # where the constraint solver starts
    mujoco.mj_forward(world.model, data)
    assert np.array_equal(data.sensordata, world.data.sensordata)
    assert np.array_equal(data.efc_force, world.data.efc_force)


def test_skipping_the_collision_pass_changes_nothing(panda_scene: Scene) -> None:
    """The scene's geoms never touch, so the world turns contacts off: the same trajectory as with them on."""
    skip, full = SimWorld(panda_scene), SimWorld(panda_scene)
    contact = int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    assert skip.model.opt.disableflags & contact
    full.model.opt.disableflags &= ~contact
    for a, b in zip(_sinusoid_run(skip, 200), _sinusoid_run(full, 200), strict=True):
        assert np.array_equal(a, b)
