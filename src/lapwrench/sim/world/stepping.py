"""The tick of :class:`~lapwrench.sim.world.SimWorld`: a Franka-like joint position servo driving the MuJoCo world.

Timing: the controller ticks at 1 kHz (:meth:`SimWorld.step`); each tick runs
``round(1 ms / timestep)`` physics steps (default timestep 0.5 ms, i.e. 2 substeps) with the
``implicitfast`` integrator, so the actuator damping is integrated implicitly. The joint servo
torque is recomputed by MuJoCo at every substep (a continuous-time analogue of the Franka's internal
joint impedance loop):

    tau_J = Kp (q_ref - q) + Kd (dq_ref - dq) + g(q),   clipped to tau_max = (87 x 4, 12 x 3) N m,

where g(q) is MuJoCo's gravity compensation of the arm and laparoscope. When no ``dq_ref`` is given
it is the finite difference of successive references, as the robot does with its command stream.

After the substeps the forward dynamics is evaluated once more (``mj_forward``), so every reading
(poses, contact force, torques, accelerations) is consistent with the state at :attr:`SimWorld.time`.

Within a tick the servo torque is a sawtooth: the reference steps at the tick, then the PD term
decays as the joint catches up (by about Kp q̇ dt per tick, several N m at 1 rad/s). A sample at the
end of the tick is therefore biased against the torque that actually moved the arm during it.
:meth:`SimWorld.joint_torque_tick_mean` is the tick mean of the link-side torque, with each
substep's velocity-dependent terms (servo damping, joint damping) at the velocity the implicit
integrator used: what a torque sensor averaged over the 1 ms sample delivers, and consistent with
the momentum change over the tick.

Cost: the per-tick glue (reference check, servo references, the tick-mean torque, the stability
checks, the contact force) runs in small numba kernels on views of ``MjData`` cached at
construction, bound to their argument types there (no per-call dispatch, nothing compiles in the
loop), so a tick costs little more than MuJoCo's own work. The position and velocity stages
of the tick's first substep are those of the previous tick's closing ``mj_forward`` whenever the
state they depend on (qpos, qvel, the equality activations and, unless they are inert, the mocap
poses) is unchanged since then, so that substep runs ``mj_step2`` only: bit for bit the same
trajectory as ``mj_step``, one position/velocity pass (about half a physics step) cheaper. After
changing the *model's* physics parameters between two ticks, call ``mujoco.mj_forward`` on
:attr:`SimWorld.data` (as before ``mj_step2``) or :meth:`SimWorld.reset`.

A mixin: the world builds the kernels' arguments (views of ``MjData``, constant and work tables) and
binds the kernels at construction (:mod:`lapwrench.sim.world.core`).
"""

from __future__ import annotations

from collections.abc import Callable

import mujoco
import numpy as np

from lapwrench.sim.world.errors import SimulationUnstableError
from lapwrench.sim.world.kernels import (
    _BAD_DEPTH,
    _BAD_DQ_REF,
    _BAD_Q_REF,
    _BAD_STATE,
    _BAD_WARNING,
    _OK_FULL,
    _OK_REUSE,
)
from lapwrench.sim.world.readings import WorldReadings

_NO_SENSORS = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)


class WorldStepping(WorldReadings):
    """The 1 kHz control tick of a :class:`~lapwrench.sim.world.SimWorld`: servo references in,
    physics substeps, stability checks."""

    n_substeps: int
    max_contact_force: float
    _begin_tick: Callable[..., int]
    _substep_torque: Callable[..., None]
    _end_tick: Callable[..., int]
    _fwd_valid: bool
    _fwd: np.ndarray
    _const: np.ndarray
    _work: np.ndarray
    _idx: np.ndarray
    _ids: np.ndarray
    _tick: float
    _no_dq_ref: np.ndarray
    _ctrl: np.ndarray
    _mocap_pos_flat: np.ndarray
    _mocap_quat_flat: np.ndarray
    _mocap_matters: bool
    _eq_active: np.ndarray
    _warn_number: np.ndarray
    _warn_idx: np.ndarray
    _warn: np.ndarray
    _depth_range: np.ndarray
    _opt: mujoco.MjOption

    @property
    def time(self) -> float:
        """Simulation time (s)."""
        return float(self.data.time)

    @property
    def timestep(self) -> float:
        """Physics timestep (s)."""
        return float(self.model.opt.timestep)

    def step(self, q_ref: np.ndarray, dq_ref: np.ndarray | None = None) -> None:
        """Advance one 1 ms control tick with the arm servoing to ``q_ref`` (rad).

        Raises :class:`SimulationUnstableError` on a non-finite reference or state, a MuJoCo
        divergence warning, or a shaft-incision contact force above ``max_contact_force``.
        """
        q_ref = np.asarray(q_ref, float)
        if q_ref.shape != self._no_dq_ref.shape:  # one value per joint
            raise SimulationUnstableError(self.time, "joint reference q_ref", repr(q_ref))
        if dq_ref is None:
            dq, use_dq = self._no_dq_ref, False
        else:
            dq, use_dq = np.asarray(dq_ref, float), True
            if dq.shape != self._no_dq_ref.shape:
                if not np.all(np.isfinite(q_ref)):
                    raise SimulationUnstableError(self.time, "joint reference q_ref", repr(q_ref))
                raise SimulationUnstableError(self.time, "joint velocity reference dq_ref", repr(dq))
        if not q_ref.flags.carray:  # the bound kernel's type: C-contiguous, aligned, writeable
            q_ref = q_ref.copy()
        if not dq.flags.carray:
            dq = dq.copy()
        code = self._begin_tick(
            q_ref, dq, use_dq, self._fwd_valid, self._const, self._work, self._idx, self._ctrl, self._qpos,
            self._qvel, self._mocap_pos_flat, self._mocap_quat_flat, self._mocap_matters, self._eq_active,
            self._fwd,
        )  # fmt: skip
        if code > _OK_FULL:
            if code == _BAD_Q_REF:
                raise SimulationUnstableError(self.time, "joint reference q_ref", repr(q_ref))
            if code == _BAD_DQ_REF:
                raise SimulationUnstableError(self.time, "joint velocity reference dq_ref", repr(dq))
            raise SimulationUnstableError(self.time, "state (qpos/qvel)", "non-finite")
        self._fwd_valid = False
        self._substeps(reuse_forward=code == _OK_REUSE)
        mujoco.mj_forward(self.model, self.data)
        self._check()

    def _substeps(self, reuse_forward: bool = False) -> None:
        """Run the tick's physics substeps, keeping the tick mean of the link-side joint torque.

        ``reuse_forward``: the position/velocity stages in ``data`` are those of the current state
        (the last ``mj_forward`` was at it), so the first substep needs ``mj_step2`` only.

        The sensors are off during the substeps: the tick's closing ``mj_forward`` computes them at
        the state every reading sees, and they never feed back into the dynamics (the same trajectory,
        without their per-substep evaluation, the F/T's force pass through the whole tree included).
        """
        m, d = self.model, self.data
        n = self.n_substeps
        args = (self._qfrc_actuator, self._qfrc_damper, self._qvel, self._idx, self._const, self._work)
        substep_torque, tick = self._substep_torque, self._tick
        opt = self._opt
        flags = opt.disableflags
        opt.disableflags = flags | _NO_SENSORS
        try:
            for k in range(n):
                if k == 0 and reuse_forward:
                    mujoco.mj_step2(m, d)
                else:
                    mujoco.mj_step(m, d)  # d.qfrc_* now hold this substep's forces, d.qvel its end velocity
                substep_torque(*args, k == n - 1, n, tick)
        finally:
            opt.disableflags = flags

    def _check(self) -> None:
        d = self.data
        code = self._end_tick(
            self._warn_number, self._warn, self._qpos, self._qvel, self._xpos, self._xmat, self._ids,
            self._depth_range, float(self.max_contact_force), d.efc_type, d.efc_id, d.efc_force,
            self._mocap_pos_flat, self._mocap_quat_flat, self._eq_active, self._fwd,
        )  # fmt: skip
        if code == _OK_REUSE:
            self._fwd_valid = True
            return
        if code == _BAD_WARNING:
            counts = self._warn_number[self._warn_idx]
            names = ["acceleration (qacc)", "velocity (qvel)", "position (qpos)"]
            bad = [n for n, c, c0 in zip(names, counts, self._warn[1], strict=True) if c != c0]
            self._warn[1] = counts
            raise SimulationUnstableError(self.time, f"MuJoCo state {', '.join(bad)}", "NaN/inf or huge (reset)")
        if code == _BAD_STATE:
            raise SimulationUnstableError(self.time, "state (qpos/qvel)", "non-finite")
        if code == _BAD_DEPTH:
            # The trocar constraint would hold a shaft that is no longer in it.
            raise SimulationUnstableError(
                self.time, "insertion depth of the incision along the shaft (m)", f"{self.insertion_depth():.4f}"
            )
        f = float(np.linalg.norm(self.contact_force()))
        raise SimulationUnstableError(self.time, "shaft-incision contact force |F| (N)", f"{f:.1f}")
