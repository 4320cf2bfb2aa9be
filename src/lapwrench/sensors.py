"""Sensor readings at the controller's edge, and their validation.

Every reading is checked before it is used: NaN, inf, wrong shape or out-of-range values reject
that reading, the wrench it drives is zeroed, and an :class:`InputEvent` says why. Nothing
invalid reaches the command.
"""

from __future__ import annotations

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
    try:
        a = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        return None
    return a if a.shape == (n,) else None


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
            elif not (np.all(np.isfinite(f)) and np.all(np.isfinite(m))):
                reject("ft", "F/T reading is not finite")
            elif np.linalg.norm(f) > self.interaction.force_range or np.linalg.norm(m) > self.interaction.torque_range:
                reject("ft", f"F/T out of range (|F|={np.linalg.norm(f):.1f} N, |M|={np.linalg.norm(m):.2f} N m)")
            else:
                out.ft = ForceTorqueReading(f, m, frame.ft.stamp)

        if frame.tactile is not None:
            v = _vector(frame.tactile.values, TACTILE_ELEMENTS)
            if v is None:
                reject("tactile", f"tactile reading must have {TACTILE_ELEMENTS} elements")
            elif not np.all(np.isfinite(v)):
                reject("tactile", "tactile reading is not finite")
            elif np.any(v < 0.0) or np.any(v > TACTILE_MAX):
                reject("tactile", "tactile element outside [0, 255]")
            else:
                out.tactile = TactileReading(v, frame.tactile.stamp)

        if frame.instruments is not None:
            pts = np.asarray(frame.instruments.points, dtype=float).reshape(-1, 2) if np.size(
                frame.instruments.points
            ) % 2 == 0 else None
            cam = self.camera
            if pts is None:
                reject("instruments", "image points must be (n, 2)")
            elif not np.all(np.isfinite(pts)):
                reject("instruments", "image point is not finite")
            elif np.any(pts < 0.0) or np.any(pts[:, 0] > cam.width) or np.any(pts[:, 1] > cam.height):
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
            elif not (np.all(np.isfinite(q)) and np.all(np.isfinite(dq))):
                reject("robot", "robot state is not finite")
            elif np.any(q < lim.position_lower - tol) or np.any(q > lim.position_upper + tol):
                reject("robot", "joint position outside the joint limits")
            elif np.any(np.abs(dq) > self.velocity_factor * lim.velocity):
                reject("robot", "joint velocity beyond the velocity limits")
            else:
                fext = None
                if frame.robot.external_force is not None:
                    fext = _vector(frame.robot.external_force, 3)
                    if fext is None or not np.all(np.isfinite(fext)) or np.linalg.norm(fext) > self.max_external_force:
                        reject("external_force", "external force estimate invalid or out of range")
                        fext = None
                out.robot = RobotReading(q, dq, fext, frame.robot.stamp)
        return out
