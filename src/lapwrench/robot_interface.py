"""The robot interface shared by the simulation and the real Franka.

A robot is driven at its control rate with joint position references, like libfranka's
``start_joint_position_control`` with ``readOnce``/``writeOnce``. Each cycle the caller reads the
state, computes, and writes exactly one command. ``RobotReading`` (see :mod:`lapwrench.sensors`)
carries q, dq and the estimated external force on the end effector in {B}. A robot that fails
raises :class:`~lapwrench.robot.errors.RobotError`.

It lives above :mod:`lapwrench.sensors` (whose readings it returns), in the loop layer, not in
:mod:`lapwrench.robot`, which the sensors themselves use.

A new robot driver implements this protocol: ``kind`` (the name of the arm's spec in
:mod:`lapwrench.robot.arms`, whose joint count sizes every vector), ``dt`` (its control period),
:meth:`~RobotInterface.connect`, :meth:`~RobotInterface.read`, :meth:`~RobotInterface.command` and
:meth:`~RobotInterface.disconnect`; the arm's spec then sets ``hardware=True``. The shipped driver is
the Franka's (:class:`lapwrench.hardware.franka.FrankaRobot`).
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

from lapwrench.robot.description import RobotKind
from lapwrench.sensors import RobotReading
from lapwrench.spatial import Vec


@runtime_checkable
class RobotInterface(Protocol):
    kind: RobotKind  # a registered arm's name (lapwrench.robot.arms.ARM_SPECS)
    dt: float  # s, the control period (the spec's command_period_s)

    def connect(self) -> RobotReading:
        """Open the connection, start joint position control and return the first state."""
        ...

    def read(self) -> RobotReading:
        """The state of the current control cycle (on hardware this waits for the cycle)."""
        ...

    def command(self, q_ref: Vec) -> None:
        """The joint position reference for this cycle."""
        ...

    def disconnect(self) -> None:
        """Stop control and release the robot (the caller brings it to rest first)."""
        ...
