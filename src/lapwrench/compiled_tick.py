"""Calling the compiled tick (:mod:`lapwrench.tick_core`) from the controller, without dispatch cost.

:class:`CompiledTick` binds the stages to this controller's argument types once, at reset (the
warm-up: compilation or the cache load happen there, never in the loop), and then calls the bound
entry points each tick with arguments of exactly those types (:func:`lapwrench.jit.bind`): the
validator hands on readings as C-contiguous float64 arrays only, Pinocchio's terms and the measured
placement of {E} come in its own layouts (:meth:`~lapwrench.robot.model.RobotModel.terms`).

When every configured cue is one of the paper's (fused into the compiled maths) the tick is one
call (:func:`~lapwrench.tick_core.tick_stage`). With cues that run in Python (plugins) it is two,
:func:`~lapwrench.tick_entry.front_into` (the kinematics, the hand's wrench, the measured axis, ΔF and
the geometry)
and :func:`~lapwrench.tick_entry.motion_tail_from`, with those cues evaluated in between on the
tick's kinematics and geometry: views of one buffer bound here, which both calls share (valid for
the tick). Both give a :class:`StageResult`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple, TypeVar

import numpy as np

from lapwrench import tick_entry as entry
from lapwrench.allocation import nullspace_wrench
from lapwrench.inputs import Reading, as_f64_c, is_f64_c, real_array
from lapwrench.jit import bind
from lapwrench.motion.measured_feedback import MeasuredFeedback
from lapwrench.rcm.adaptive import AdaptiveRcm, AdaptiveState
from lapwrench.rcm.geometry import TaskGeometry
from lapwrench.robot.model import Kinematics, KinematicTerms
from lapwrench.sensors import ForceTorqueReading, InstrumentObservation, RobotReading, TactileReading, ValidInputs
from lapwrench.spatial import Mat, Vec, Wrench, cholesky_factor
from lapwrench.tick_core import SaturationInputs, tick_stage
from lapwrench.tick_entry import front_into, front_size, front_views, motion_tail_from
from lapwrench.tick_params import TickParams
from lapwrench.wrenches.base import Cue, CueError, TickContext, call_cue
from lapwrench.wrenches.ft_zero import FtTare


class StageResult(NamedTuple):
    """One tick of the compiled maths, before the saturation step."""

    e_R: Vec
    p_R: Vec
    p_G: Vec
    residual_lateral: Vec
    residual: Vec | None
    wrenches: dict[str, Vec]
    W_n: Vec
    tau: Vec
    delta: float
    contacts: int
    non_finite: bool
    admitted: bool  # the desired acceleration met every limit and ``ref`` is the next reference
    ref: tuple[Vec, Vec, Vec] | None  # the next reference, when admitted or saturated in the compiled step
    clamped: bool
    at_bound: int  # bit mask of the limit rows (joint box, then envelope) at a bound when saturated: bit i, row i
    telemetry: dict[str, tuple[float, ...]]  # the Python cues' telemetry by cue name
    cue_faults: tuple[str, ...] = ()  # Python cues whose output was dropped this tick


class _Extra(NamedTuple):
    W: Mat  # one null-space wrench [moment; force] per row
    points: Mat  # the point each is taken about
    D: Mat  # summed damping matrices of the null-space cues that have one
    task_F: Vec  # summed force of the task-space cues, at p_R
    by_name: dict[str, Vec]  # every Python cue's wrench about p_G
    telemetry: dict[str, tuple[float, ...]]
    faults: tuple[str, ...]  # cues whose output was dropped this tick (non-finite), and why


_ZERO3 = np.zeros(3)
_NO_TACTILE = np.zeros(64)
_NO_POINTS = np.zeros((0, 2))
_NO_EXTRA = _Extra(np.zeros((0, 6)), np.zeros((0, 3)), np.zeros((6, 6)), np.zeros(3), {}, {}, ())
_NO_TELEMETRY: dict[str, tuple[float, ...]] = {}


def _reading_args(inputs: ValidInputs) -> entry.ReadingArgs:
    """The readings as the stages take them: F/T force, torque, valid; tactile values, valid; image points
    (the validator hands on C-contiguous float64 arrays of the right shapes only, the bound types)."""
    ft, tactile, obs = inputs.ft, inputs.tactile, inputs.instruments
    return (
        _ZERO3 if ft is None else ft.force, _ZERO3 if ft is None else ft.torque, ft is not None,
        _NO_TACTILE if tactile is None else tactile.values, tactile is not None,
        _NO_POINTS if obs is None else obs.points,
    )


class CompiledTick:
    """The compiled stages bound to one controller's state and configuration."""

    def __init__(
        self, params: TickParams, rcm: AdaptiveRcm, feedback: MeasuredFeedback, cues: Sequence[Cue], tare: FtTare,
    ) -> None:
        """``cues``: the cues that run in Python (not fused into the compiled maths), in order; ``tare``: where
        the handle F/T was tared, and its zero (stepped by the compiled tick)."""
        self.params = params
        self.rcm = rcm
        self.feedback = feedback
        self.tare = tare
        self.cues = list(cues)
        self.null_cues = [c for c in self.cues if c.priority == "null"]
        self.task_cues = [c for c in self.cues if c.priority == "task"]
        self.cues_in_order = self.null_cues + self.task_cues  # the order of the rows of the stacked wrenches
        self.sat = SaturationInputs.allocate(params.q_lo.shape[0])
        self.cue_inputs = ReadOnlyInputs()

    # -- arguments of fixed types --------------------------------------------------------------
    # the readings as they are: the validator hands on C-contiguous float64 arrays of the right shapes only
    # (sensors.py), the types the stages are bound to
    def _placement(self, inputs: ValidInputs) -> tuple[Mat, Vec, bool]:
        """{E}'s measured placement (:meth:`MeasuredFeedback.measured_placement`) this tick."""
        robot = inputs.robot
        return self.feedback.measured_placement(None if robot is None else robot.q)

    def _state_args(
        self, terms: KinematicTerms, inputs: ValidInputs, placement: tuple[Mat, Vec, bool]
    ) -> entry.StateArgs:
        """The arguments both entry stages begin with: the terms, the adaptive RCM state and parameters, the
        robot's force estimate, the measured-feedback offsets and {E}'s measured placement."""
        robot = inputs.robot
        ext = None if robot is None else robot.external_force
        R_m, p_m, has_measured = placement
        return (
            terms, self.rcm.state, self.rcm.params, _ZERO3 if ext is None else ext, ext is not None,
            self.feedback.offsets, R_m, p_m, has_measured,
        )

    def _front_args(
        self, terms: KinematicTerms, inputs: ValidInputs, placement: tuple[Mat, Vec, bool]
    ) -> entry.FrontArgs:
        return (*self._state_args(terms, inputs, placement), *_reading_args(inputs)[:5], self.tare, self.params)

    def _tick_args(
        self, terms: KinematicTerms, inputs: ValidInputs, placement: tuple[Mat, Vec, bool], ddq_ref: Vec,
        stopping: bool, R_E0: Mat, may_admit: bool,
    ) -> entry.TickArgs:
        return (
            *self._state_args(terms, inputs, placement), *_reading_args(inputs), as_f64_c(ddq_ref), bool(stopping),
            R_E0, bool(may_admit), self.sat, self.tare, self.params,
        )

    def _motion_args(
        self, s_star: float, inputs: ValidInputs, extra: _Extra, ddq_ref: Vec, stopping: bool, R_E0: Mat,
        may_admit: bool,
    ) -> entry.MotionArgs:
        return (
            self._buf, s_star, *_reading_args(inputs), extra.W, extra.points, extra.D, extra.task_F,
            as_f64_c(ddq_ref), bool(stopping), R_E0, float(self.feedback.offsets[3]), bool(may_admit), self.sat,
            self.params,
        )

    # -- warm-up -------------------------------------------------------------------------------
    def bind(self, terms: KinematicTerms, R_E0: Mat) -> None:
        """Compile (or load from the cache) every stage for these argument types, and run each once
        on copies of the state, so the warm-up changes nothing."""
        live_rcm, live_offsets = self.rcm.state, self.feedback.offsets
        self.rcm.state = AdaptiveState(*(a.copy() for a in live_rcm))
        self.feedback.offsets = live_offsets.copy()
        live_zero = self.tare
        self.tare = FtTare(live_zero.R_H0, live_zero.zero.copy())
        try:
            none = ValidInputs()
            zero = np.zeros(terms.q.shape[0])
            at_rest = self._placement(none)
            args = self._tick_args(terms, none, at_rest, zero, False, R_E0, True)
            self._tick_stage = bind(tick_stage, *args)
            self._tick_stage(*args)
            one = np.zeros((1, 6)), np.zeros((1, 3)), np.zeros(3)
            self._about_p_G = bind(nullspace_wrench, *one)  # eq (39) for one wrench: the eq (38) sum of one
            n = terms.q.shape[0]
            self._buf = np.zeros(front_size(n))  # the kinematics and geometry of the ticks with Python cues
            self._kin, self._geo = front_views(self._buf, n, 0.0)  # views of it, cut once
            # the cues read read-only views of them: a plugin writing into ctx.kin.q (say) would change the
            # motion stage's input, which reads the buffer back (a jump of the reference)
            self._cue_kin, self._cue_geo = _read_only_tuple(self._kin), _read_only_tuple(self._geo)
            if self.cues:  # the damping matrices' check (_checked_damping) compiled now, never in the loop
                cholesky_factor(np.eye(6), np.empty((6, 6)), 0.0)
            f_args = (*self._front_args(terms, none, at_rest), self._buf)
            self._front_into = bind(front_into, *f_args)
            _, s_star, _ = self._front_into(*f_args)
            m_args = self._motion_args(s_star, none, _NO_EXTRA, zero, False, R_E0, True)
            self._motion_tail_from = bind(motion_tail_from, *m_args)
            self._motion_tail_from(*m_args)
        finally:
            self.rcm.state, self.feedback.offsets, self.tare = live_rcm, live_offsets, live_zero

    # -- one tick ------------------------------------------------------------------------------
    def run(
        self, t: float, terms: KinematicTerms, inputs: ValidInputs, ddq_ref: Vec, stopping: bool, R_E0: Mat,
        may_admit: bool,
    ) -> StageResult:
        """The compiled maths of one tick (module docstring); when the result is not admitted, :attr:`sat`
        holds the saturation inputs."""
        placement = self._placement(inputs)
        if self.cues:
            return self._run_with_cues(t, terms, inputs, placement, ddq_ref, stopping, R_E0, may_admit)
        args = self._tick_args(terms, inputs, placement, ddq_ref, stopping, R_E0, may_admit)
        vec3, has_res, W, ref, at, delta, contacts, non_finite, admitted, saturated, clamped = self._tick_stage(*args)
        e_R, p_R, p_G, F_lat, residual = vec3  # row views (unpacking is cheaper than indexing)
        W_r, W_h, W_c, W_f, W_n = W
        q, dq, ddq, tau = ref
        return StageResult._make((  # _make: without the keyword-handling constructor (1 µs at 1 kHz)
            e_R, p_R, p_G, F_lat, residual if has_res else None, self._paper_wrenches(W_r, W_h, W_c, W_f), W_n, tau,
            delta, contacts, non_finite, admitted, (q, dq, ddq) if admitted or saturated else None, clamped, at,
            _NO_TELEMETRY, (),
        ))

    def _paper_wrenches(self, W_r: Vec, W_h: Vec, W_c: Vec, W_f: Vec) -> dict[str, Vec]:
        """The compiled cues' wrenches by name, those the configuration has on."""
        p = self.params
        if p.cue_interaction and p.cue_tracking and p.cue_viscous:
            return {"rcm": W_r, "interaction": W_h, "tracking": W_c, "viscous": W_f}  # the common case
        on = (("rcm", W_r, True), ("interaction", W_h, p.cue_interaction), ("tracking", W_c, p.cue_tracking),
              ("viscous", W_f, p.cue_viscous))
        return {name: w for name, w, used in on if used}

    def _run_with_cues(
        self, t: float, terms: KinematicTerms, inputs: ValidInputs, placement: tuple[Mat, Vec, bool], ddq_ref: Vec,
        stopping: bool, R_E0: Mat, may_admit: bool,
    ) -> StageResult:
        vec3, s_star, has_residual = self._front_into(*self._front_args(terms, inputs, placement), self._buf)
        e_R, p_R, p_G, F_lat, residual, force, torque = vec3  # row views of a new array: what outlives the tick
        if inputs.ft is not None:  # the cues and the motion stage read the hand's wrench (lapwrench.wrenches.ft_zero)
            inputs.ft = ForceTorqueReading(force, torque, inputs.ft.stamp)
        geo = self._cue_geo._replace(s_star=s_star)
        extra = self._evaluate_cues(TickContext(t, self._cue_kin, geo, self.cue_inputs(inputs)))
        W, ref, at, delta, contacts, non_finite, admitted, saturated, clamped = self._motion_tail_from(
            *self._motion_args(s_star, inputs, extra, ddq_ref, stopping, R_E0, may_admit)
        )
        W_r, W_h, W_c, W_f, W_n = W
        q, dq, ddq, tau = ref
        wrenches = {**self._paper_wrenches(W_r, W_h, W_c, W_f), **extra.by_name}
        return StageResult._make((
            e_R, p_R, p_G, F_lat, residual if has_residual else None, wrenches, W_n, tau, delta, contacts,
            non_finite, admitted, (q, dq, ddq) if admitted or saturated else None, clamped, at, extra.telemetry,
            extra.faults,
        ))

    def _evaluate_cues(self, ctx: TickContext) -> _Extra:
        """The Python cues this tick: the null-space wrenches with their points and summed damping, the
        task-space force at p_R, every wrench about p_G (eq 39) by name, and the telemetry.

        What a plugin returns is checked: a non-finite wrench or damping matrix, or a damping matrix whose
        symmetric part is not positive semi-definite (it would feed energy in), is dropped for this tick
        (zero, and a fault named in ``faults``), like a rejected sensor reading; anything that is not a
        wrench of 3-vectors, a 6 x 6 matrix or one number per telemetry field is a :class:`CueError`
        (the loop turns it into an alarm and a stop to rest).
        """
        p_G = self._geo.p_G  # the cues read a read-only view of it
        faults: list[str] = []
        null = [_checked_wrench(c, call_cue(c, "compute", ctx), p_G, faults) for c in self.null_cues]
        task = [_checked_wrench(c, call_cue(c, "compute", ctx), p_G, faults) for c in self.task_cues]
        D = np.zeros((6, 6))
        for c in self.null_cues:
            Dc = call_cue(c, "damping_matrix", ctx)
            if Dc is not None:
                D += _checked_damping(c, Dc, faults)
        task_F = np.zeros(3)
        for w in task:  # a task-space cue acts at p_R through J_R: its force (its moment is not used)
            task_F += w.force
        checked = null + task
        # every wrench [moment; force] a row, every point a row (null-space cues first): one copy each
        W = np.concatenate([a for w in checked for a in (w.moment, w.force)]).reshape(-1, 6)
        points = np.concatenate([w.point for w in checked]).reshape(-1, 3)
        n = len(null)
        about = self._about_p_G
        return _Extra(
            W[:n],
            points[:n],
            D,
            task_F,
            {c.name: about(W[i:i + 1], points[i:i + 1], p_G) for i, c in enumerate(self.cues_in_order)},
            {c.name: _checked_telemetry(c, call_cue(c, "telemetry", ctx, w))
             for c, w in zip(self.cues_in_order, checked, strict=True) if c.telemetry_fields},
            tuple(faults),
        )


_A = TypeVar("_A")


def _read_only(a: _A) -> _A:
    """A read-only view of ``a`` (``a`` itself when it is not an array)."""
    if not isinstance(a, np.ndarray):
        return a
    v = a.view()
    v.setflags(write=False)
    return v


_Views = TypeVar("_Views", Kinematics, TaskGeometry)


def _read_only_tuple(t: _Views) -> _Views:
    """The named tuple ``t`` with read-only views of its arrays."""
    return type(t)._make(_read_only(a) for a in t)


class ReadOnlyInputs:
    """The tick's inputs as the Python cues see them: read-only views of the readings (the arrays are the
    sources' own, the measured joints the supervisor's, and the motion stage reads them after the cues) and
    a copy of the events (the tick's result carries the list). A tactile or image reading handed on again
    (the sources keep their latest between samples) is viewed once."""

    def __init__(self) -> None:
        self.last_tactile: tuple[TactileReading | None, TactileReading | None] = (None, None)
        self.last_instruments: tuple[InstrumentObservation | None, InstrumentObservation | None] = (None, None)

    def __call__(self, inputs: ValidInputs) -> ValidInputs:
        ft, tac, obs, rob, ro = inputs.ft, inputs.tactile, inputs.instruments, inputs.robot, _read_only
        if tac is not None and tac is not self.last_tactile[0]:
            self.last_tactile = (tac, TactileReading(ro(tac.values), tac.stamp))
        if obs is not None and obs is not self.last_instruments[0]:
            self.last_instruments = (obs, InstrumentObservation(ro(obs.points), obs.stamp))
        return ValidInputs(
            None if ft is None else ForceTorqueReading(ro(ft.force), ro(ft.torque), ft.stamp),
            None if tac is None else self.last_tactile[1],
            None if obs is None else self.last_instruments[1],
            None if rob is None else RobotReading(ro(rob.q), ro(rob.dq), ro(rob.external_force), rob.stamp),
            list(inputs.events),
            {k: Reading(ro(r.value), r.stamp) for k, r in inputs.extra.items()} if inputs.extra else {},
        )


def _vec3(x: object) -> Vec | None:
    """``x`` as a float64 3-vector if it holds three real numbers (not text, booleans or objects), else None."""
    if is_f64_c(x) and x.shape == (3,):
        return x  # the common case, checked cheaply
    a = real_array(x)
    return a if a is not None and a.shape == (3,) else None


def _checked_wrench(cue: Cue, w: object, p_G: Vec, faults: list[str]) -> Wrench:
    """``w`` as a wrench of float 3-vectors; a non-finite one becomes zero (and a fault)."""
    if not isinstance(w, Wrench):
        raise CueError(f"cue {cue.name!r} returned {type(w).__name__}, not a Wrench")
    moment, force, point = _vec3(w.moment), _vec3(w.force), _vec3(w.point)
    if moment is None or force is None or point is None:
        raise CueError(f"cue {cue.name!r} returned a Wrench whose moment, force and point are not 3-vectors")
    if not all(map(math.isfinite, [*moment.tolist(), *force.tolist(), *point.tolist()])):  # one pass, no ufuncs
        faults.append(f"cue {cue.name!r}: non-finite wrench; dropped this tick")
        return Wrench.zero(p_G)
    if moment is w.moment and force is w.force and point is w.point:
        return w  # already float64 3-vectors: as it is
    return Wrench(moment, force, point)


def _checked_damping(cue: Cue, D: object, faults: list[str]) -> Mat:
    a = real_array(D)
    if a is None or a.shape != (6, 6):
        what = "not real numbers" if a is None else f"shape {a.shape}"
        raise CueError(f"cue {cue.name!r}: damping_matrix must be 6 x 6 real numbers, got {what}")
    if not np.isfinite(a).all():
        faults.append(f"cue {cue.name!r}: non-finite damping matrix; dropped this tick")
        return np.zeros((6, 6))
    S = a + a.T  # its symmetric part (twice), nudged so that a semi-definite one factors
    S.flat[::7] += 1e-9 * max(1.0, float(np.abs(S).max()))
    if not cholesky_factor(S, np.empty((6, 6)), 0.0):  # -D J_G θ̇ with D not >= 0 feeds energy in: the arm moves
        faults.append(f"cue {cue.name!r}: damping matrix not positive semi-definite; dropped this tick")
        return np.zeros((6, 6))
    return a


def _number(x: object) -> float:
    """``x`` as a float if it is a real number (text, bytes and ints beyond a float's range are not)."""
    if isinstance(x, str | bytes | bytearray):
        raise TypeError(f"{type(x).__name__} {x!r:.40}")
    try:
        return float(x)  # type: ignore[arg-type]
    except OverflowError as exc:
        raise ValueError(f"{exc}") from exc


def _checked_telemetry(cue: Cue, values: object) -> tuple[float, ...]:
    try:
        out = tuple(map(_number, values))  # type: ignore[call-overload]
    except (TypeError, ValueError) as exc:
        raise CueError(f"cue {cue.name!r}: telemetry must be numbers ({exc})") from exc
    if len(out) != len(cue.telemetry_fields):
        raise CueError(f"cue {cue.name!r}: {len(out)} telemetry values for fields {cue.telemetry_fields}")
    return out
