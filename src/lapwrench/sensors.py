"""Sensor readings at the controller's edge, and their validation.

Every reading is checked before it is used: NaN, inf, wrong shape or out-of-range values reject
that reading, the wrench it drives is zeroed, and an :class:`InputEvent` says why. Nothing
invalid reaches the command.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from lapwrench.config import CameraConfig, InteractionConfig
from lapwrench.inputs import InputSpec, Reading, fresh_stamp, real_array
from lapwrench.jit import bind, kernel
from lapwrench.robot.limits import JointLimits
from lapwrench.spatial import Vec

TACTILE_ELEMENTS = 64
TACTILE_MAX = 255.0


@dataclass(frozen=True)
class ForceTorqueReading:
    """Handle F/T sensor: force (N) and torque (N m) applied by the hand, in the handle frame {H}."""

    force: Vec
    torque: Vec
    stamp: float = 0.0


@dataclass(frozen=True)
class TactileReading:
    """The 64 grip-array elements, 0 for no contact, (0, 255] when loaded."""

    values: Vec
    stamp: float = 0.0


@dataclass(frozen=True)
class InstrumentObservation:
    """Image points (u_i, v_i) in pixels of the detected instruments; ``stamp`` is the frame's time."""

    points: Vec
    stamp: float = 0.0


@dataclass(frozen=True)
class RobotReading:
    """Measured joint state and the robot's estimate of the external force on the end effector.

    ``external_force`` is the total external force acting on the end effector, in {B} (see
    :mod:`lapwrench.rcm.adaptive` for the sign convention).
    """

    q: Vec
    dq: Vec
    external_force: Vec | None = None
    stamp: float = 0.0


@dataclass(frozen=True)
class SensorFrame:
    """Everything the controller reads in one tick; a missing source is ``None``."""

    time: float
    ft: ForceTorqueReading | None = None
    tactile: TactileReading | None = None
    instruments: InstrumentObservation | None = None
    robot: RobotReading | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)  # registered inputs by name (lapwrench.inputs)


@dataclass(frozen=True)
class InputEvent:
    time: float
    source: str
    message: str


@dataclass
class ValidInputs:
    """The readings that passed validation this tick (``None`` = rejected or absent)."""

    ft: ForceTorqueReading | None = None
    tactile: TactileReading | None = None
    instruments: InstrumentObservation | None = None
    robot: RobotReading | None = None
    events: list[InputEvent] = field(default_factory=list)
    extra: dict[str, Reading] = field(default_factory=dict)  # registered inputs that passed their spec


# Compared with ==, not is: arrays from numba's cached kernels (the tick's own reference, fed back as the
# robot reading) carry an equal float64 dtype of their own, and would take the converting path every tick.
_F64 = np.dtype(np.float64)


def _vector(x: object, n: int) -> Vec | None:
    """``x`` as a C-contiguous float vector of length n, or None if it is not one."""
    if type(x) is np.ndarray and x.dtype == _F64 and x.ndim == 1 and len(x) == n and x.flags.carray:
        return x  # the common case, checked cheaply (no shape tuple built)
    if (x.size if isinstance(x, np.ndarray) else len(x) if isinstance(x, list | tuple) else n) != n:
        return None  # refused before a copy: a reading of 10^7 values must not cost the tick its conversion
    a = real_array(x)
    return a if a is not None and a.shape == (n,) else None


# Status codes of the compiled checks below (0: valid).
OK, NOT_FINITE, OUT_OF_RANGE, OUTSIDE_LIMITS, TOO_FAST = 0, 1, 2, 3, 4


@kernel
def ft_status(f: Vec, m: Vec, force_range: float, torque_range: float) -> tuple[int, float, float]:
    """F/T reading: (status, |F|, |M|)."""
    nf, nm = math.sqrt(f @ f), math.sqrt(m @ m)
    if not (math.isfinite(nf) and math.isfinite(nm)):
        return NOT_FINITE, nf, nm
    return (OUT_OF_RANGE if nf > force_range or nm > torque_range else OK), nf, nm


@kernel
def range_status(v: Vec, lo: float, hi: float) -> int:
    """Every element finite and inside [lo, hi]."""
    for x in v:
        if not math.isfinite(x):
            return NOT_FINITE
    for x in v:
        if x < lo or x > hi:
            return OUT_OF_RANGE
    return OK


@kernel
def points_status(pts: Vec, width: float, height: float) -> int:
    """Image points (n x 2) finite and inside the image."""
    for i in range(pts.shape[0]):
        if not (math.isfinite(pts[i, 0]) and math.isfinite(pts[i, 1])):
            return NOT_FINITE
    for i in range(pts.shape[0]):
        if pts[i, 0] < 0.0 or pts[i, 1] < 0.0 or pts[i, 0] > width or pts[i, 1] > height:
            return OUT_OF_RANGE
    return OK


@kernel
def joint_status(q: Vec, dq: Vec, lower: Vec, upper: Vec, tolerance: float, dq_max: Vec) -> int:
    """Joint positions inside the limits (± tolerance) and speeds under ``dq_max``, all finite."""
    for i in range(q.shape[0]):
        if not (math.isfinite(q[i]) and math.isfinite(dq[i])):
            return NOT_FINITE
    for i in range(q.shape[0]):
        if q[i] < lower[i] - tolerance or q[i] > upper[i] + tolerance:
            return OUTSIDE_LIMITS
    for i in range(q.shape[0]):
        if abs(dq[i]) > dq_max[i]:
            return TOO_FAST
    return OK


@kernel
def frame_status(
    f: Vec, m: Vec, force_range: float, torque_range: float, tactile: Vec, points: Vec, width: float,
    height: float, q: Vec, dq: Vec, lower: Vec, upper: Vec, tolerance: float, dq_max: Vec, f_ext: Vec,
    f_ext_limit: float,
) -> tuple[int, float, float, int, int, int, int]:
    """Every compiled check of one frame in one call (a call from Python costs more than the checks):
    (:func:`ft_status`'s three values, the tactile array's :func:`range_status`, :func:`points_status`,
    :func:`joint_status`, and the external force's: finite, each component and the norm within
    ``f_ext_limit``). The caller passes placeholders for readings that are absent and ignores their status."""
    s_ft, nf, nm = ft_status(f, m, force_range, torque_range)
    s_ext = range_status(f_ext, -f_ext_limit, f_ext_limit)
    if s_ext == OK and math.sqrt(f_ext @ f_ext) > f_ext_limit:
        s_ext = OUT_OF_RANGE
    return (s_ft, nf, nm, range_status(tactile, 0.0, TACTILE_MAX), points_status(points, width, height),
            joint_status(q, dq, lower, upper, tolerance, dq_max), s_ext)


_Z3 = np.zeros(3)
_NO_POINTS = np.zeros((0, 2))


class InputValidator:
    """Checks each reading against its shape, finiteness and physical range."""

    def __init__(
        self,
        interaction: InteractionConfig,
        camera: CameraConfig,
        limits: JointLimits,
        max_image_age: float,
        position_tolerance: float = 0.02,
        velocity_factor: float = 1.5,
        max_external_force: float = 300.0,
        max_instruments: int = 8,
        inputs: Mapping[str, InputSpec] | None = None,
    ) -> None:
        self.interaction = interaction
        self.camera = camera
        self.limits = limits
        self.max_image_age = max_image_age
        self.position_tolerance = position_tolerance
        self.velocity_factor = velocity_factor
        self.max_external_force = max_external_force
        self.max_instruments = max_instruments
        self.inputs = dict(inputs or {})  # the registered inputs the cues ask for, by name
        self._q_lo = np.ascontiguousarray(limits.position_lower, dtype=np.float64)
        self._q_hi = np.ascontiguousarray(limits.position_upper, dtype=np.float64)
        self._dq_max = np.ascontiguousarray(velocity_factor * limits.velocity, dtype=np.float64)
        self._force_range = float(interaction.force_range)
        self._torque_range = float(interaction.torque_range)
        self._width, self._height = float(camera.width), float(camera.height)
        # The checks bound to their argument types (C-contiguous float64 arrays, which _vector and
        # real_array guarantee, and floats): no numba dispatch per frame.
        n = self._q_lo.shape[0]
        self._zero_q, self._zero_tactile = np.zeros(n), np.zeros(TACTILE_ELEMENTS)
        self._frame_status = bind(
            frame_status, _Z3, _Z3, 0.0, 0.0, self._zero_tactile, _NO_POINTS, 0.0, 0.0, self._zero_q, self._zero_q,
            self._q_lo, self._q_hi, 0.0, self._dq_max, _Z3, 0.0,
        )

    def validate(self, frame: SensorFrame) -> ValidInputs:
        """The frame's readings that pass their checks; an :class:`InputEvent` for each one rejected.
        A valid reading is passed on as it is (the same object) when its arrays already are C-contiguous
        float64, else rebuilt around converted copies.

        Shapes and types are checked here, every value in one compiled call (:func:`frame_status`);
        then each reading's verdict, in the order ft, tactile, instruments, robot, registered inputs."""
        t = frame.time
        events: list[InputEvent] = []
        ft_r, tac_r, obs_r, rob_r = frame.ft, frame.tactile, frame.instruments, frame.robot
        n = self._q_lo.shape[0]
        f = m = v = fext = None
        if ft_r is not None:
            f, m = _vector(ft_r.force, 3), _vector(ft_r.torque, 3)
        if tac_r is not None:
            v = _vector(tac_r.values, TACTILE_ELEMENTS)
        pts, pts_why = (None, "") if obs_r is None else self._points(obs_r.points)
        q = dq = None
        if rob_r is not None:
            q, dq = _vector(rob_r.q, n), _vector(rob_r.dq, n)
            if rob_r.external_force is not None:
                fext = _vector(rob_r.external_force, 3)
        f_in, m_in = (f, m) if f is not None and m is not None else (None, None)  # both vectors, or neither
        q_in, dq_in = (q, dq) if q is not None and dq is not None else (None, None)
        s_ft, nf, nm, s_tac, s_pts, s_rob, s_ext = self._frame_status(
            _Z3 if f_in is None else f_in, _Z3 if m_in is None else m_in, self._force_range, self._torque_range,
            self._zero_tactile if v is None else v, _NO_POINTS if pts is None else pts, self._width, self._height,
            self._zero_q if q_in is None else q_in, self._zero_q if dq_in is None else dq_in, self._q_lo, self._q_hi,
            self.position_tolerance, self._dq_max, _Z3 if fext is None else fext, self.max_external_force,
        )
        ft = None if ft_r is None else self._ft(ft_r, f_in, m, s_ft, nf, nm, t, events)
        tactile = None if tac_r is None else self._tactile(tac_r, v, s_tac, t, events)
        instruments = None if obs_r is None else self._instruments(frame, pts, pts_why, s_pts, events)
        robot = None if rob_r is None else self._robot(rob_r, q_in, dq, fext, s_rob, s_ext, t, events)
        extra = self._extra(frame.extra, t, events) if frame.extra else {}
        return ValidInputs(ft, tactile, instruments, robot, events, extra)

    def _extra(self, readings: Mapping[str, Any], t: float, events: list[InputEvent]) -> dict[str, Reading]:
        """The registered inputs' readings that pass their :class:`~lapwrench.inputs.InputSpec`."""
        valid: dict[str, Reading] = {}
        for name, r in readings.items():
            spec = self.inputs.get(name) if isinstance(name, str) else None
            if spec is None:
                events.append(InputEvent(t, "inputs", f"reading of an input no cue asked for: {str(name)[:40]!r}"))
                continue
            reading, why = spec.check(r, t)
            if reading is None:
                events.append(InputEvent(t, name, why))
            else:
                valid[name] = reading
        return valid

    def _ft(
        self, r: ForceTorqueReading, f: Vec | None, m: Vec | None, status: int, nf: float, nm: float, t: float,
        events: list[InputEvent],
    ) -> ForceTorqueReading | None:
        if f is None or m is None:
            events.append(InputEvent(t, "ft", "F/T reading must be two 3-vectors"))
            return None
        if status == NOT_FINITE:
            events.append(InputEvent(t, "ft", "F/T reading is not finite"))
        elif status == OUT_OF_RANGE:
            events.append(InputEvent(t, "ft", f"F/T out of range (|F|={nf:.1f} N, |M|={nm:.2f} N m)"))
        else:
            return r if f is r.force and m is r.torque else ForceTorqueReading(f, m, r.stamp)
        return None

    def _tactile(
        self, r: TactileReading, v: Vec | None, status: int, t: float, events: list[InputEvent]
    ) -> TactileReading | None:
        if v is None:
            events.append(InputEvent(t, "tactile", f"tactile reading must have {TACTILE_ELEMENTS} elements"))
            return None
        if status == NOT_FINITE:
            events.append(InputEvent(t, "tactile", "tactile reading is not finite"))
        elif status == OUT_OF_RANGE:
            events.append(InputEvent(t, "tactile", "tactile element outside [0, 255]"))
        else:
            return r if v is r.values else TactileReading(v, r.stamp)
        return None

    def _robot(
        self, r: RobotReading, q: Vec | None, dq: Vec | None, fext: Vec | None, status: int, ext_status: int,
        t: float, events: list[InputEvent],
    ) -> RobotReading | None:
        if q is None or dq is None:
            n = self._q_lo.shape[0]
            events.append(InputEvent(t, "robot", f"robot state must hold {n} joint positions and velocities"))
            return None
        if status == NOT_FINITE:
            events.append(InputEvent(t, "robot", "robot state is not finite"))
        elif status == OUTSIDE_LIMITS:
            events.append(InputEvent(t, "robot", "joint position outside the joint limits"))
        elif status == TOO_FAST:
            events.append(InputEvent(t, "robot", "joint velocity beyond the velocity limits"))
        else:
            if r.external_force is not None and (fext is None or ext_status != OK):
                events.append(InputEvent(t, "external_force", "external force estimate invalid or out of range"))
                fext = None
            if q is r.q and dq is r.dq and fext is r.external_force:
                return r
            return RobotReading(q, dq, fext, r.stamp)
        return None

    def _points(self, points: object) -> tuple[Vec | None, str]:
        """The image points as a C-contiguous float64 (n, 2) array, or None and why not (shape, count)."""
        listed = isinstance(points, list | tuple) or (isinstance(points, np.ndarray) and points.ndim > 0)
        count = len(points) if listed else 0  # type: ignore[arg-type]
        if count > self.max_instruments or (isinstance(points, np.ndarray) and points.size > 2 * count):
            # counted before any copy: a million detections must not cost the tick their conversion
            return None, (f"{count} detections in one frame (at most {self.max_instruments}): a detector fault"
                          if count > self.max_instruments else "image points must be (n, 2) real numbers")
        pts = real_array(points)
        if pts is None or pts.ndim != 2 or pts.shape[1] != 2:
            return None, "image points must be (n, 2) real numbers"
        if len(pts) > self.max_instruments:
            # eq (8) sums over every detection: 100 at one corner would ask 1000 N of the scope
            return None, f"{len(pts)} detections in one frame (at most {self.max_instruments}): a detector fault"
        return pts, ""

    def _instruments(
        self, frame: SensorFrame, pts: Vec | None, why: str, status: int, events: list[InputEvent]
    ) -> InstrumentObservation | None:
        assert frame.instruments is not None
        cam = self.camera

        def reject(source: str, message: str) -> None:
            events.append(InputEvent(frame.time, source, message))

        if pts is None:
            reject("instruments", why)
        elif status == NOT_FINITE:
            reject("instruments", "image point is not finite")
        elif status == OUT_OF_RANGE:
            reject("instruments", f"image point outside the {cam.width}x{cam.height} image")
        elif not fresh_stamp(frame.instruments.stamp, frame.time, self.max_image_age):
            reject("instruments", f"detection older than {self.max_image_age} s")
        else:
            obs = frame.instruments
            return obs if pts is obs.points else InstrumentObservation(pts, obs.stamp)
        return None
