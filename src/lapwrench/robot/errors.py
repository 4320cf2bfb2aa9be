"""The error every robot (the simulated arm, franky-sim, the real Franka) raises when it fails."""

from __future__ import annotations


class RobotError(RuntimeError):
    """The robot refused a command, lost the connection or reported a fault."""
