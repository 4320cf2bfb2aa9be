"""The one small interface every wrench source implements.

A source reads the tick's :class:`TickContext` (kinematics, RCM/closest-point geometry and the
validated sensor inputs) and returns a :class:`~lapwrench.spatial.Wrench` in {B} about a point of
its choice. The allocator moves it to the closest point with eq (39). To add a cue, write a class
with a ``name`` and a ``compute(ctx) -> Wrench`` method and pass it to the controller as an extra
null-space source.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, runtime_checkable

from lapwrench.rcm.geometry import TaskGeometry
from lapwrench.robot.model import Kinematics
from lapwrench.sensors import ValidInputs
from lapwrench.spatial import Mat, Wrench


@dataclass(frozen=True)
class TickContext:
    time: float
    kin: Kinematics
    geometry: TaskGeometry
    inputs: ValidInputs


@runtime_checkable
class WrenchSource(Protocol):
    """A cue turned into an equivalent wrench."""

    name: str

    def compute(self, ctx: TickContext) -> Wrench: ...


@runtime_checkable
class DampingSource(Protocol):
    """A source whose wrench is linear in the closest-point twist: W = -D J_G θ̇.

    The semi-implicit integrator treats such terms implicitly.
    """

    def damping_matrix(self) -> Mat: ...
