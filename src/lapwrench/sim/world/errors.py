"""The error :class:`~lapwrench.sim.world.SimWorld` raises when the simulation diverges."""

from __future__ import annotations

from lapwrench.robot.errors import RobotError


class SimulationUnstableError(RobotError):
    """The simulation diverged. ``time`` (s) and ``quantity`` name what went wrong and when."""

    def __init__(self, time: float, quantity: str, value: float | str) -> None:
        self.time = time
        self.quantity = quantity
        self.value = value
        super().__init__(f"simulation unstable at t = {time:.4f} s: {quantity} = {value}")

    def __reduce__(self) -> tuple[type[SimulationUnstableError], tuple[float, str, float | str]]:
        """Pickle by the constructor's arguments (``args`` holds only the message), so the error can
        cross a process boundary (the demo's and the sweeps' worker processes)."""
        return type(self), (self.time, self.quantity, self.value)
