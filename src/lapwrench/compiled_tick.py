"""Calling the compiled tick (:mod:`lapwrench.tick_core`) from the controller, without dispatch cost.

:class:`CompiledTick` binds the stages to this controller's argument types once, at reset (the
warm-up: compilation or the cache load happen there, never in the loop), and then calls the bound
entry points each tick with arguments of exactly those types (:func:`lapwrench.jit.bind`):
external arrays are made C-contiguous float64 first.

Without extra wrench sources the tick is one call (:func:`~lapwrench.tick_core.tick_stage`). With
them it is two, :func:`~lapwrench.tick_core.geometry_stage` and
:func:`~lapwrench.tick_core.motion_stage`, with the extra sources evaluated in Python on the
tick's geometry in between. Both give a :class:`StageResult`.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from lapwrench.jit import bind
from lapwrench.motion.measured_feedback import NO_AXIS, MeasuredFeedback
from lapwrench.motion.reference_shaper import advance_reference
from lapwrench.rcm.adaptive import AdaptiveRcm, AdaptiveState, residual_force
from lapwrench.robot.model import Kinematics, KinematicTerms, ScopeAxis, assemble_kinematics
from lapwrench.sensors import ValidInputs
from lapwrench.spatial import Mat, Vec
from lapwrench.tick_core import (
    SaturationInputs,
    fill_saturation_inputs,
    geometry_stage,
    motion_stage,
    saturation_stage,
    tick_stage,
)
from lapwrench.tick_params import TickParams
from lapwrench.wrenches.base import DampingSource, TickContext, WrenchSource

BUILT_IN_WRENCHES = ("rcm", "interaction", "tracking", "viscous")


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
    at_bound: np.ndarray  # the limit rows (joint box, then envelope) at a bound when saturated


class _Extra(NamedTuple):
    W: Mat  # one wrench [moment; force] per row
    points: Mat  # the point each is taken about
    D: Mat  # summed damping matrices of the damping sources
    by_name: dict[str, Vec]


_F64 = np.dtype(np.float64)


def _f64(x: object) -> Vec:
    """A C-contiguous float64 array (itself when it is one already): the bound argument type."""
    if type(x) is np.ndarray and x.dtype is _F64 and x.flags.c_contiguous:
        return x  # the common case (validated readings), checked cheaply
    return np.ascontiguousarray(x, dtype=np.float64)


def _points(x: object) -> Mat:
    """Image points as a C-contiguous float64 (n, 2) array (itself when it is one already)."""
    a = _f64(x)
    return a if a.ndim == 2 and a.shape[1] == 2 else a.reshape(-1, 2)


_ZERO3 = np.zeros(3)
_NO_TACTILE = np.zeros(64)
_NO_POINTS = np.zeros((0, 2))
_NO_ROWS = np.zeros(0, dtype=bool)
_NO_EXTRA = _Extra(np.zeros((0, 6)), np.zeros((0, 3)), np.zeros((6, 6)), {})


class CompiledTick:
    """The compiled stages bound to one controller's state and configuration."""

    def __init__(
        self, params: TickParams, rcm: AdaptiveRcm, feedback: MeasuredFeedback, extra_sources: Sequence[WrenchSource]
    ) -> None:
        self.check_names(extra_sources)
        self.params = params
        self.rcm = rcm
        self.feedback = feedback
        self.extra_sources = list(extra_sources)
        self.sat = SaturationInputs.allocate(params.q_lo.shape[0])

    @staticmethod
    def check_names(extra_sources: Sequence[WrenchSource]) -> None:
        """Raise ValueError when two sources share a name or one takes a built-in wrench's name."""
        names = [s.name for s in extra_sources]
        clash = sorted({n for n in names if names.count(n) > 1 or n in BUILT_IN_WRENCHES})
        if clash:
            raise ValueError(f"wrench source names must be unique and none of {BUILT_IN_WRENCHES}: {clash}")

    # -- arguments of fixed types --------------------------------------------------------------
    def _sensor_args(self, inputs: ValidInputs) -> tuple[object, ...]:
        ft, tactile, obs = inputs.ft, inputs.tactile, inputs.instruments
        return (
            _ZERO3 if ft is None else _f64(ft.force), _ZERO3 if ft is None else _f64(ft.torque), ft is not None,
            _NO_TACTILE if tactile is None else _f64(tactile.values), tactile is not None,
            _NO_POINTS if obs is None else _points(obs.points),
        )

    def _tick_args(
        self, terms: KinematicTerms, Minv: Mat, inputs: ValidInputs, measured: ScopeAxis, has_measured: bool,
        ddq_ref: Vec, stopping: bool, R_E0: Mat, may_admit: bool,
    ) -> tuple[object, ...]:
        robot, ft, tactile, obs = inputs.robot, inputs.ft, inputs.tactile, inputs.instruments
        ext = None if robot is None else robot.external_force
        return (  # _sensor_args written out: this runs every tick
            terms, Minv, self.rcm.state, self.rcm.params, _ZERO3 if ext is None else _f64(ext), ext is not None,
            self.feedback.offsets, measured, bool(has_measured),
            _ZERO3 if ft is None else _f64(ft.force), _ZERO3 if ft is None else _f64(ft.torque), ft is not None,
            _NO_TACTILE if tactile is None else _f64(tactile.values), tactile is not None,
            _NO_POINTS if obs is None else _points(obs.points),
            _f64(ddq_ref), bool(stopping), R_E0, bool(may_admit), self.sat, self.params,
        )

    def _geometry_args(
        self, kin: Kinematics, residual: Vec | None, measured: ScopeAxis, has_measured: bool
    ) -> tuple[object, ...]:
        r = _ZERO3 if residual is None else _f64(residual)
        return (kin, self.rcm.state, self.rcm.params, r, residual is not None, self.feedback.offsets, measured,
                bool(has_measured), self.params)

    def _motion_args(
        self, kin: Kinematics, Minv: Mat, geo: object, inputs: ValidInputs, extra: _Extra, ddq_ref: Vec,
        stopping: bool, R_E0: Mat,
    ) -> tuple[object, ...]:
        return (kin, Minv, geo, *self._sensor_args(inputs), extra.W, extra.points, extra.D, _f64(ddq_ref),
                bool(stopping), R_E0, float(self.feedback.offsets[3]), self.params)

    # -- warm-up -------------------------------------------------------------------------------
    def bind(self, terms: KinematicTerms, Minv: Mat, R_E0: Mat) -> None:
        """Compile (or load from the cache) every stage for these argument types, and run each once
        on copies of the state, so the warm-up changes nothing."""
        live_rcm, live_offsets = self.rcm.state, self.feedback.offsets
        self.rcm.state = AdaptiveState(*(a.copy() for a in live_rcm))
        self.feedback.offsets = live_offsets.copy()
        try:
            none = ValidInputs()
            zero = np.zeros(terms.q.shape[0])
            args = self._tick_args(terms, Minv, none, NO_AXIS, False, zero, False, R_E0, True)
            self._tick_stage = bind(tick_stage, *args)
            self._tick_stage(*args)
            kin = assemble_kinematics(*terms)
            g_args = self._geometry_args(kin, None, NO_AXIS, False)
            self._geometry_stage = bind(geometry_stage, *g_args)
            geo, _ = self._geometry_stage(*g_args)
            m_args = self._motion_args(kin, Minv, geo, none, _NO_EXTRA, zero, False, R_E0)
            self._motion_stage = bind(motion_stage, *m_args)
            self._motion_stage(*m_args)
            s_args = (self.sat, Minv, terms.q, terms.dq, self.params)
            self._saturation_stage = bind(saturation_stage, *s_args)
            self._saturation_stage(*s_args)
        finally:
            self.rcm.state, self.feedback.offsets = live_rcm, live_offsets

    # -- one tick ------------------------------------------------------------------------------
    def run(
        self, t: float, terms: KinematicTerms, Minv: Mat, inputs: ValidInputs, ddq_ref: Vec, stopping: bool,
        R_E0: Mat, may_admit: bool,
    ) -> StageResult:
        """The compiled maths of one tick (module docstring); :attr:`sat` then holds the saturation inputs."""
        measured, has_measured = self.feedback.measured_axis(None if inputs.robot is None else inputs.robot.q)
        if self.extra_sources:
            return self._run_with_extras(t, terms, Minv, inputs, measured, has_measured, ddq_ref, stopping, R_E0,
                                         may_admit)
        args = self._tick_args(terms, Minv, inputs, measured, has_measured, ddq_ref, stopping, R_E0, may_admit)
        vec3, W, ref, at, tau, delta, contacts, has_res, non_finite, admitted, saturated, clamped = self._tick_stage(
            *args
        )
        e_R, p_R, p_G, F_lat, residual = vec3  # row views (unpacking is cheaper than indexing)
        W_r, W_h, W_c, W_f, W_n = W
        wrenches = {"rcm": W_r, "interaction": W_h, "tracking": W_c, "viscous": W_f}
        return StageResult(
            e_R, p_R, p_G, F_lat, residual if has_res else None, wrenches, W_n, tau, delta, contacts,
            non_finite, admitted, tuple(ref) if admitted or saturated else None, clamped, at,
        )

    def _run_with_extras(
        self, t: float, terms: KinematicTerms, Minv: Mat, inputs: ValidInputs, measured: ScopeAxis,
        has_measured: bool, ddq_ref: Vec, stopping: bool, R_E0: Mat, may_admit: bool,
    ) -> StageResult:
        kin = assemble_kinematics(*terms)
        robot, ft = inputs.robot, inputs.ft
        residual = None
        if ft is not None and robot is not None and robot.external_force is not None:
            residual = residual_force(kin.R_H @ _f64(ft.force), _f64(robot.external_force))
        geo, F_lat = self._geometry_stage(*self._geometry_args(kin, residual, measured, has_measured))
        extra = self._extra(TickContext(t, kin, geo, inputs))
        o = self._motion_stage(*self._motion_args(kin, Minv, geo, inputs, extra, ddq_ref, stopping, R_E0))
        fill_saturation_inputs(self.sat, o, kin, self.params.a_max)
        admitted = o.admitted and may_admit
        ref, clamped, at = None, False, _NO_ROWS
        if admitted:
            q, dq, ddq, clamped = advance_reference(kin.q, kin.dq, o.a_d, o.a_lo, o.a_hi, self.params.dt)
            ref = (q, dq, ddq)
        elif may_admit:
            saturated, rows, at, clamped = self._saturation_stage(self.sat, Minv, kin.q, kin.dq, self.params)
            ref = (rows[0], rows[1], rows[2]) if saturated else None
        wrenches = {"rcm": o.W_r, "interaction": o.W_h, "tracking": o.W_c, "viscous": o.W_f, **extra.by_name}
        return StageResult(geo.e_R, geo.p_R, geo.p_G, F_lat, residual, wrenches, o.W_n, o.tau, o.delta, o.contacts,
                           o.non_finite, admitted, ref, bool(clamped), at)

    def _extra(self, ctx: TickContext) -> _Extra:
        """The extra sources' wrenches, the points they are taken about, their summed damping matrix."""
        ws = [s.compute(ctx) for s in self.extra_sources]
        D = np.zeros((6, 6))
        for s in self.extra_sources:
            if isinstance(s, DampingSource):
                D += s.damping_matrix()
        return _Extra(
            _f64(np.array([w.vector for w in ws]).reshape(-1, 6)),
            _f64(np.array([w.point for w in ws], dtype=float).reshape(-1, 3)),
            D,
            {s.name: w.vector for s, w in zip(self.extra_sources, ws, strict=True)},
        )

