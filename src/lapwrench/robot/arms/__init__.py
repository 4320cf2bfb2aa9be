"""The registry of arms: one module per arm (``panda``, ``fr3``, ``ur5``, ``xarm7``), each defining one
:class:`~lapwrench.robot.arms.spec.ArmSpec` as ``SPEC``.

Everything else reads an arm through :data:`ARM_SPECS` / :func:`arm_spec`. Adding a simulated arm
is one module here plus its name in :data:`lapwrench.robot_kinds.ROBOT_KINDS` (what the configuration
accepts).
"""

from __future__ import annotations

from lapwrench.robot.arms import fr3, panda, ur5, xarm7
from lapwrench.robot.arms.spec import (
    ArmSpec,
    JointLimitTable,
    PackageUrdf,
    RobotDescriptionError,
    ScopeMount,
    SimLook,
    UrdfFile,
)
from lapwrench.robot_kinds import ROBOT_KINDS, unknown_kind_message

ARM_SPECS: dict[str, ArmSpec] = {m.SPEC.name: m.SPEC for m in (panda, fr3, ur5, xarm7)}
"""Every shipped arm by name (the order of :data:`~lapwrench.robot_kinds.ROBOT_KINDS`)."""

if tuple(ARM_SPECS) != ROBOT_KINDS:  # pragma: no cover - a registration mistake, caught at import
    raise RuntimeError(f"lapwrench.robot_kinds.ROBOT_KINDS {ROBOT_KINDS} != registered arms {tuple(ARM_SPECS)}")

MAX_JOINTS = max(spec.n_joints for spec in ARM_SPECS.values())
"""The most joints any shipped arm has: the per-joint width of fixed-size formats (the real-time bus's
cycle rows), which also record the actual count."""


def arm_spec(name: str) -> ArmSpec:
    """The spec of arm ``name``; ``ValueError`` (one line) for a name that is not registered."""
    try:
        return ARM_SPECS[name]
    except (KeyError, TypeError):
        raise ValueError(unknown_kind_message(str(name))) from None


__all__ = [
    "ARM_SPECS", "MAX_JOINTS", "ArmSpec", "JointLimitTable", "PackageUrdf", "RobotDescriptionError", "ScopeMount",
    "SimLook", "UrdfFile", "arm_spec",
]
