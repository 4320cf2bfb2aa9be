"""What one arm is, as data: :class:`ArmSpec` and its parts.

A robot is one spec (issue 13, "Robots as data", robosuite style): where its description comes from,
its joints, the links that differ between descriptions, its limits with their published source, its
start poses, the simulated joint servo, how it treats position commands, where the laparoscope
mounts and whether lapwrench has a hardware driver for it. One short module per arm in this package
defines one; :mod:`lapwrench.robot.arms` registers them. Nothing here imports the rest of lapwrench
but its errors.
"""

from __future__ import annotations

import functools
import importlib.metadata
import math
from dataclasses import dataclass, field
from pathlib import Path

from lapwrench.robot.errors import RobotDescriptionError

__all__ = ["ArmSpec", "JointLimitTable", "PackageUrdf", "RobotDescriptionError", "ScopeMount", "SimLook", "UrdfFile"]


@dataclass(frozen=True)
class PackageUrdf:
    """A URDF file shipped inside an installed Python distribution (found through its file list, so
    the package need not be importable): ``distribution`` (PyPI name) and the path's ``suffix``."""

    distribution: str
    suffix: str

    def path(self) -> Path:
        """The file's absolute path; :class:`RobotDescriptionError` naming the package if absent.
        Found once per process (:func:`_locate`): the package's file list has thousands of entries."""
        return _locate(self.distribution, self.suffix)


@dataclass(frozen=True)
class UrdfFile:
    """A URDF file of one's own, by its path (its meshes relative to it or absolute)."""

    file: Path

    def path(self) -> Path:
        """The file's path (read and checked by :func:`lapwrench.robot.description.build_urdf`)."""
        return Path(self.file)


@functools.cache
def _locate(distribution: str, suffix: str) -> Path:
    """The installed file of ``distribution`` whose path ends with ``suffix`` (a failure is not cached)."""
    try:
        files = importlib.metadata.files(distribution) or []
    except importlib.metadata.PackageNotFoundError as exc:
        raise RobotDescriptionError(
            f"this robot's description comes with the '{distribution}' package: pip install {distribution}"
        ) from exc
    for f in files:
        if str(f).endswith(suffix):
            found = Path(str(f.locate()))
            if found.is_file():
                return found
    raise RobotDescriptionError(f"{distribution} is installed but ships no {suffix}")


@dataclass(frozen=True)
class JointLimitTable:
    """The published per-joint limits the description does not carry (position limits come from it):
    velocity (rad/s), acceleration (rad/s^2), jerk (rad/s^3), torque (N m), torque rate (N m/s).
    Each spec module cites its source next to the numbers."""

    velocity: tuple[float, ...]
    acceleration: tuple[float, ...]
    jerk: tuple[float, ...]
    torque: tuple[float, ...]
    torque_rate: tuple[float, ...]


@dataclass(frozen=True)
class ScopeMount:
    """Where the laparoscope's {E} sits: ``link`` (the flange) and the fixed ``xyz`` (m) / ``rpy``
    (rad) offset from it, chosen so that +z of {E} runs along the shaft."""

    link: str
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)


@dataclass(frozen=True)
class SimLook:
    """How the simulated arm is drawn where its description has no usable geometry: link capsules of
    ``capsule_radius`` (m) between successive joints, in colour ``rgba``."""

    rgba: tuple[float, float, float, float] = (0.92, 0.92, 0.94, 1.0)
    capsule_radius: float = 0.045


_PER_JOINT = ("home_pose", "sim_start_pose", "servo_stiffness", "servo_damping", "sim_torque_bias")
_PER_JOINT_LIMITS = ("velocity", "acceleration", "jerk", "torque", "torque_rate")


@dataclass(frozen=True)
class ArmSpec:
    """One arm as data; every per-joint tuple has one value per entry of ``joint_names``.

    - ``description``: the URDF (gripper and everything below ``mount.link`` are removed, the scope
      added: :func:`lapwrench.robot.description.build_urdf`); ``base_link`` its root.
    - ``limits``: velocity/acceleration/jerk/torque/torque-rate tables (position: the description's).
    - ``home_pose``: the controller's default start (scope straight down, well inside the limits: the
      virtual closed loop, the real-time warm-up). ``sim_start_pose``: the simulated scene's start
      (flange about 0.48 m above the base and 0.5 m in front of it, scope straight down; the scene
      places the trocar and the phantom below the scope there).
    - ``servo_stiffness`` (N m/rad), ``servo_damping`` (N m s/rad): the simulated joint position
      servo. ``sim_torque_bias`` (N m): the constant error the simulation puts on the measured joint
      torques behind the external force estimate.
    - ``differentiates_commands``/``command_period_s``: whether the robot differentiates each joint
      position command over one period (the Franka does, over 1 ms, so every command must respect the
      velocity/acceleration/jerk limits) and the period it expects.
    - ``mount``: the default scope mount. ``hardware``: lapwrench has a driver for the real arm.
    """

    name: str
    description: PackageUrdf | UrdfFile
    joint_names: tuple[str, ...]
    base_link: str
    mount: ScopeMount
    limits: JointLimitTable
    home_pose: tuple[float, ...]
    sim_start_pose: tuple[float, ...]
    servo_stiffness: tuple[float, ...]
    servo_damping: tuple[float, ...]
    sim_torque_bias: tuple[float, ...]
    differentiates_commands: bool
    command_period_s: float
    hardware: bool
    look: SimLook = field(default_factory=SimLook)

    def __post_init__(self) -> None:
        n = len(self.joint_names)
        bad = [k for k in _PER_JOINT if len(getattr(self, k)) != n]
        bad += [f"limits.{k}" for k in _PER_JOINT_LIMITS if len(getattr(self.limits, k)) != n]
        if bad:
            raise ValueError(f"{self.name}: {', '.join(bad)} need one value per joint ({n})")
        for k in _PER_JOINT_LIMITS:
            values = getattr(self.limits, k)
            if not all(isinstance(v, int | float) and math.isfinite(v) and v > 0.0 for v in values):
                raise ValueError(f"{self.name}: limits.{k} must be finite positive numbers, got {values!r}")
        if not self.command_period_s > 0.0:
            raise ValueError(f"{self.name}: command_period_s must be positive, got {self.command_period_s!r}")

    @property
    def n_joints(self) -> int:
        """The arm's joint count (the length of every per-joint vector: q, dq, limits, commands)."""
        return len(self.joint_names)

    @property
    def flange_link(self) -> str:
        """The link the scope mounts on (everything below it, a gripper, is removed)."""
        return self.mount.link

    def urdf_path(self) -> Path:
        """The description's file (:meth:`PackageUrdf.path`)."""
        return self.description.path()
