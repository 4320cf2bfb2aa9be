"""The error every robot (the simulated arm, franky-sim, the real Franka) raises when it fails, and the
error of a robot description that cannot be used."""

from __future__ import annotations


class RobotError(RuntimeError):
    """The robot refused a command, lost the connection or reported a fault."""


class RobotDescriptionError(RuntimeError):
    """The robot description could not be found, parsed or used (the message names the file)."""
