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


_F64 = np.dtype(np.float64)


def _vector(x: object, n: int) -> Vec | None:
    """``x`` as a C-contiguous float vector of length n, or None if it is not one."""
    if type(x) is np.ndarray and x.dtype is _F64 and x.shape == (n,) and x.flags.carray:
        return x  # the common case, checked cheaply
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
        # The checks bound to their argument types (C-contiguous float64 arrays, which _vector and
        # _real_array guarantee, and floats): no numba dispatch per reading.
        v3, q = np.zeros(3), np.zeros(self._q_lo.shape[0])
        self._ft_status = bind(ft_status, v3, v3, 0.0, 0.0)
        self._range_status = bind(range_status, v3, 0.0, 0.0)
        self._points_status = bind(points_status, np.zeros((1, 2)), 0.0, 0.0)
        self._joint_status = bind(joint_status, q, q, self._q_lo, self._q_hi, 0.0, self._dq_max)

    def validate(self, frame: SensorFrame) -> ValidInputs:
        """The frame's readings that pass their checks; an :class:`InputEvent` for each one rejected.
        A valid reading is passed on as it is (the same object) when its arrays already are C-contiguous
        float64, else rebuilt around converted copies."""
        t = frame.time
        events: list[InputEvent] = []
        ft = None if frame.ft is None else self._ft(frame.ft, t, events)
        tactile = None if frame.tactile is None else self._tactile(frame.tactile, t, events)
        instruments = None if frame.instruments is None else self._instruments(frame, events)
        robot = None if frame.robot is None else self._robot(frame.robot, t, events)
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

    def _ft(self, r: ForceTorqueReading, t: float, events: list[InputEvent]) -> ForceTorqueReading | None:
        f, m = _vector(r.force, 3), _vector(r.torque, 3)
        if f is None or m is None:
            events.append(InputEvent(t, "ft", "F/T reading must be two 3-vectors"))
            return None
        status, nf, nm = self._ft_status(f, m, self._force_range, self._torque_range)
        if status == NOT_FINITE:
            events.append(InputEvent(t, "ft", "F/T reading is not finite"))
        elif status == OUT_OF_RANGE:
            events.append(InputEvent(t, "ft", f"F/T out of range (|F|={nf:.1f} N, |M|={nm:.2f} N m)"))
        else:
            return r if f is r.force and m is r.torque else ForceTorqueReading(f, m, r.stamp)
        return None

    def _tactile(self, r: TactileReading, t: float, events: list[InputEvent]) -> TactileReading | None:
        v = _vector(r.values, TACTILE_ELEMENTS)
        if v is None:
            events.append(InputEvent(t, "tactile", f"tactile reading must have {TACTILE_ELEMENTS} elements"))
            return None
        status = self._range_status(v, 0.0, TACTILE_MAX)
        if status == NOT_FINITE:
            events.append(InputEvent(t, "tactile", "tactile reading is not finite"))
        elif status == OUT_OF_RANGE:
            events.append(InputEvent(t, "tactile", "tactile element outside [0, 255]"))
        else:
            return r if v is r.values else TactileReading(v, r.stamp)
        return None

    def _robot(self, r: RobotReading, t: float, events: list[InputEvent]) -> RobotReading | None:
        n = self._q_lo.shape[0]
        q, dq = _vector(r.q, n), _vector(r.dq, n)
        if q is None or dq is None:
            events.append(InputEvent(t, "robot", f"robot state must hold {n} joint positions and velocities"))
            return None
        status = self._joint_status(q, dq, self._q_lo, self._q_hi, self.position_tolerance, self._dq_max)
        if status == NOT_FINITE:
            events.append(InputEvent(t, "robot", "robot state is not finite"))
        elif status == OUTSIDE_LIMITS:
            events.append(InputEvent(t, "robot", "joint position outside the joint limits"))
        elif status == TOO_FAST:
            events.append(InputEvent(t, "robot", "joint velocity beyond the velocity limits"))
        else:
            fext = None
            if r.external_force is not None:
                fext = _vector(r.external_force, 3)
                limit = self.max_external_force
                if fext is None or self._range_status(fext, -limit, limit) or math.sqrt(fext.dot(fext)) > limit:
                    events.append(InputEvent(t, "external_force", "external force estimate invalid or out of range"))
                    fext = None
            if q is r.q and dq is r.dq and fext is r.external_force:
                return r
            return RobotReading(q, dq, fext, r.stamp)
        return None

    def _instruments(self, frame: SensorFrame, events: list[InputEvent]) -> InstrumentObservation | None:
        assert frame.instruments is not None
        cam = self.camera

        def reject(source: str, message: str) -> None:
            events.append(InputEvent(frame.time, source, message))

        pts = real_array(frame.instruments.points)
        if pts is None or pts.ndim != 2 or pts.shape[1] != 2:
            reject("instruments", "image points must be (n, 2) real numbers")
            return None
        if len(pts) > self.max_instruments:
            # eq (8) sums over every detection: 100 at one corner would ask 1000 N of the scope
            n, most = len(pts), self.max_instruments
            reject("instruments", f"{n} detections in one frame (at most {most}): a detector fault")
            return None
        status = self._points_status(pts, float(cam.width), float(cam.height))
        if status == NOT_FINITE:
            reject("instruments", "image point is not finite")
        elif status == OUT_OF_RANGE:
            reject("instruments", f"image point outside the {cam.width}x{cam.height} image")
        elif not fresh_stamp(frame.instruments.stamp, frame.time, self.max_image_age):
            reject("instruments", f"detection older than {self.max_image_age} s")
        else:
            obs = frame.instruments
            return obs if pts is obs.points else InstrumentObservation(pts, obs.stamp)
        return None
