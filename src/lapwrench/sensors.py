"""Sensor readings at the controller's edge, and their validation.

Every reading is checked before it is used: NaN, inf, wrong shape or out-of-range values reject
that reading, the wrench it drives is zeroed, and an :class:`InputEvent` says why. Nothing
invalid reaches the command.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from lapwrench.config import CameraConfig, InteractionConfig
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


def _vector(x: object, n: int) -> Vec | None:
    """``x`` as a float vector of length n, or None if it is not one."""
    if type(x) is np.ndarray and x.dtype == np.float64:
        return x if x.shape == (n,) else None
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        return None
    return a if a.shape == (n,) else None


def _finite(*arrays: Vec) -> bool:
    # a sum is NaN/inf iff some element is (or it overflows, which is out of range anyway)
    return all(math.isfinite(a.sum()) for a in arrays)


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
    ) -> None:
        self.interaction = interaction
        self.camera = camera
        self.limits = limits
        self.max_image_age = max_image_age
        self.position_tolerance = position_tolerance
        self.velocity_factor = velocity_factor
        self.max_external_force = max_external_force

    def validate(self, frame: SensorFrame) -> ValidInputs:
        out = ValidInputs()
        t = frame.time

        def reject(source: str, message: str) -> None:
            out.events.append(InputEvent(t, source, message))

        if frame.ft is not None:
            f, m = _vector(frame.ft.force, 3), _vector(frame.ft.torque, 3)
            if f is None or m is None:
                reject("ft", "F/T reading must be two 3-vectors")
            elif not _finite(f, m):
                reject("ft", "F/T reading is not finite")
            elif math.sqrt(f @ f) > self.interaction.force_range or math.sqrt(m @ m) > self.interaction.torque_range:
                reject("ft", f"F/T out of range (|F|={math.sqrt(f @ f):.1f} N, |M|={math.sqrt(m @ m):.2f} N m)")
            else:
                out.ft = ForceTorqueReading(f, m, frame.ft.stamp)

        if frame.tactile is not None:
            v = _vector(frame.tactile.values, TACTILE_ELEMENTS)
            if v is None:
                reject("tactile", f"tactile reading must have {TACTILE_ELEMENTS} elements")
            elif not _finite(v):
                reject("tactile", "tactile reading is not finite")
            elif v.min() < 0.0 or v.max() > TACTILE_MAX:
                reject("tactile", "tactile element outside [0, 255]")
            else:
                out.tactile = TactileReading(v, frame.tactile.stamp)

        if frame.instruments is not None:
            raw = frame.instruments.points
            pts = np.asarray(raw, dtype=float) if np.ndim(raw) == 2 and np.shape(raw)[1:] == (2,) else None
            cam = self.camera
            if pts is None:
                reject("instruments", "image points must be (n, 2)")
            elif not _finite(pts):
                reject("instruments", "image point is not finite")
            elif len(pts) and (pts.min() < 0.0 or pts[:, 0].max() > cam.width or pts[:, 1].max() > cam.height):
                reject("instruments", f"image point outside the {cam.width}x{cam.height} image")
            elif not np.isfinite(frame.instruments.stamp) or t - frame.instruments.stamp > self.max_image_age:
                reject("instruments", f"detection older than {self.max_image_age} s")
            else:
                out.instruments = InstrumentObservation(pts, frame.instruments.stamp)

        if frame.robot is not None:
            q, dq = _vector(frame.robot.q, 7), _vector(frame.robot.dq, 7)
            lim = self.limits
            tol = self.position_tolerance
            if q is None or dq is None:
                reject("robot", "robot state must hold 7 joint positions and velocities")
            elif not _finite(q, dq):
                reject("robot", "robot state is not finite")
            elif (q < lim.position_lower - tol).any() or (q > lim.position_upper + tol).any():
                reject("robot", "joint position outside the joint limits")
            elif (np.abs(dq) > self.velocity_factor * lim.velocity).any():
                reject("robot", "joint velocity beyond the velocity limits")
            else:
                fext = None
                if frame.robot.external_force is not None:
                    fext = _vector(frame.robot.external_force, 3)
                    if fext is None or not _finite(fext) or math.sqrt(fext @ fext) > self.max_external_force:
                        reject("external_force", "external force estimate invalid or out of range")
                        fext = None
                out.robot = RobotReading(q, dq, fext, frame.robot.stamp)
        return out
