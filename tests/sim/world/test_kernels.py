"""The compiled tick kernels of SimWorld against the plain MuJoCo step, compiled and not."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import mujoco
import numpy as np

from lapwrench.sim.scene.build import Scene
from lapwrench.sim.world import CONTROL_DT, SimWorld


class _PlainStep:
    """SimWorld.step as first written: numpy on fresh MjData lookups, a full mj_step per substep."""

    def __init__(self, world: SimWorld) -> None:
        self.w = world
        self.q_prev = world.q_ref

    def step(self, q_ref: np.ndarray, dq_ref: np.ndarray | None = None) -> np.ndarray:
        w, m, d = self.w, self.w.model, self.w.data
        v = w.scene.arm_dof_adr
        kp, kv = np.asarray(w.gains.stiffness, float), np.asarray(w.gains.damping, float)
        if dq_ref is None:
            dq_ref = (q_ref - self.q_prev) / CONTROL_DT
        self.q_prev = q_ref.copy()
        act = [m.actuator(f"servo_{n}").id for n in w.scene.arm_joint_names]
        d.ctrl[act] = q_ref + (kv / kp) * dq_ref
        total = np.zeros(7)
        v_tick = d.qvel[v].copy()
        armature, damping = m.dof_armature[v], m.dof_damping[v]
        for _ in range(w.n_substeps):
            v_start = d.qvel[v].copy()
            mujoco.mj_step(m, d)
            tau = d.qfrc_actuator[v]
            kv_eff = kv * (np.abs(tau) < np.array([87.0] * 4 + [12.0] * 3) - 1e-9)
            total += tau + d.qfrc_damper[v] - (kv_eff + damping) * (d.qvel[v] - v_start)
        tick = w.n_substeps * m.opt.timestep
        tau_mean = total / w.n_substeps - armature * (d.qvel[v] - v_tick) / tick
        mujoco.mj_forward(m, d)
        return tau_mean


def _plain_contact_force(world: SimWorld) -> np.ndarray:
    d = world.data
    weld = world.model.equality("trocar_weld").id
    rows = np.flatnonzero(
        (d.efc_type[: d.nefc] == mujoco.mjtConstraint.mjCNSTR_EQUALITY) & (d.efc_id[: d.nefc] == weld)
    )
    return np.zeros(3) if rows.size < 3 else -d.efc_force[rows[:3]]


def _script(world: SimWorld, i: int) -> tuple[np.ndarray, np.ndarray | None]:
    """Scripted loads and references of tick ``i`` (instrument moved, hand and housing loads, dq_ref)."""
    t = (i + 1) * CONTROL_DT
    if i == 100:
        world.set_hand_wrench(force=[4.0, -2.0, 1.0], torque=[0.0, 0.05, 0.1])
    if i == 250:
        world.set_housing_load(world.housing_load_for_shift(np.array([0.004, -0.003])))
    if i % 3 == 0:
        world.set_instrument_tip(1, world.port_position(1) + np.array([0.02, 0.06 * np.sin(t), -0.12]))
    amp = np.array([0.02, 0.02, 0.02, 0.03, 0.05, 0.03, 0.3])
    q_ref = world.scene.q0 + amp * np.sin(2 * np.pi * 1.5 * t) * min(1.0, t / 0.1)
    dq_ref = amp * 2 * np.pi * 1.5 * np.cos(2 * np.pi * 1.5 * t) if 300 <= i < 350 else None
    return q_ref, dq_ref


_UNCOMPILED_RUN = """
import json, sys
import numpy as np
from lapwrench.sim.robot import ForceEstimateConfig, SimRobot
from lapwrench.sim.world import SimWorld
w = SimWorld()
r = SimRobot(w, estimate=ForceEstimateConfig(torque_noise=0.05, torque_bias=0.1, seed=3))
r.connect()
w.set_hand_wrench(force=np.array([3.0, -1.0, 0.5]))
out = []
for i in range(150):
    if i % 5 == 0:
        w.set_instrument_tip(0, w.port_position(0) + np.array([0.0, 0.03 * np.sin(i / 50), -0.12]))
    r.command(w.scene.q0 + 0.02 * np.sin(i / 30))
    rd = r.read()
    out.append([*w.data.qpos, *w.joint_torque_tick_mean(), *w.contact_force(), *rd.external_force])
print(json.dumps(out))
"""


def test_compiled_step_matches_the_plain_step_bit_for_bit(panda_scene: Scene) -> None:
    """The kernels, the cached views and the reused first-substep forward change no bit of the
    trajectory: state, tick-mean torque, sensors, contact force and readings are identical."""
    fast, plain = SimWorld(panda_scene), SimWorld(panda_scene)
    ref = _PlainStep(plain)
    for i in range(500):
        if i == 400:
            q = panda_scene.q0 + 0.02
            fast.reset(q)
            plain.reset(q)
            ref.q_prev = plain.q_ref
        q_ref, dq_ref = _script(fast, i)
        _script(plain, i)
        fast.step(q_ref, dq_ref)
        tau_mean = ref.step(q_ref, dq_ref)
        for name in ("qpos", "qvel", "qacc", "sensordata", "efc_force", "xpos", "mocap_quat", "ctrl"):
            np.testing.assert_array_equal(getattr(fast.data, name), getattr(plain.data, name), err_msg=name)
        np.testing.assert_array_equal(fast.joint_torque_tick_mean(), tau_mean)
        np.testing.assert_array_equal(fast.contact_force(), _plain_contact_force(plain))
    assert np.linalg.norm(fast.contact_force()) > 1.0


def test_kernels_run_uncompiled_with_the_same_results() -> None:
    """Under NUMBA_DISABLE_JIT=1 the kernels are plain Python: same physics bit for bit (the kernels
    do the same float operations), the observer's force to 1e-9 N."""
    runs = {}
    for jit in ("0", "1"):
        env = {**os.environ, "NUMBA_DISABLE_JIT": jit, "MUJOCO_GL": "egl"}
        res = subprocess.run(
            [sys.executable, "-c", _UNCOMPILED_RUN], env=env, capture_output=True, text=True, timeout=300
        )
        assert res.returncode == 0, res.stderr
        runs[jit] = np.array(json.loads(res.stdout.strip().splitlines()[-1]))
    compiled, plain = runs["0"], runs["1"]
    np.testing.assert_array_equal(compiled[:, :-3], plain[:, :-3])
    np.testing.assert_allclose(compiled[:, -3:], plain[:, -3:], rtol=0, atol=1e-9)
    assert np.max(np.abs(compiled[:, -3:])) > 1.0
