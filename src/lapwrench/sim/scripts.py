"""The scripted surgeon of the paper's scenarios as reusable objects: what the hand and the
instruments do, tick by tick, in a :class:`~lapwrench.sim.world.SimWorld`.

- :class:`ViewAdjustment` (Fig. 4): a hand grips and turns the view by a fixed angle, then lets go.
- :class:`NeedleSearch` (Fig. 6-7): tracking only → handle & tracking → handle dominant, search →
  release, tracking re-engages on the instrument brought to the needle.
- :class:`Workflow` (Fig. 9): handle to the first gauze pad, tracking while it is picked up and the
  second one found, handle again toward the gallbladder, tracking to the end.

A script is called once per 1 ms tick, before the controller's cycle, with the world and the
script's own time ``t`` (s, 0 at its first call): it moves the instruments, sets the hand's wrench
on the world (:meth:`~lapwrench.sim.world.SimWorld.set_hand_wrench`) and returns the hand's grip
force (N). The scenarios (:mod:`lapwrench.sim.scenarios`) step one from the start of a run; the
browser UI (:mod:`lapwrench.ui.session`) plays one from the moment its button is pressed, and adds
the page's own hand on top. Durations scale with ``time_scale`` as the scenarios' do; ``variation``
scales every scripted hand (:meth:`~lapwrench.sim.variation.WorldVariation.hand`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import ClassVar, Protocol

import numpy as np

from lapwrench.sim.surgeon import HandGuide, InstrumentPath, rotate_axis
from lapwrench.sim.variation import WorldVariation
from lapwrench.sim.world import CONTROL_DT, SimWorld

TISSUE_DEPTH = 0.145  # m below the incision (the phantom's tissue surface)
# Largest push (N) of the scripted surgeon's speed-driven hand in the tracking scenarios. With the
# paper's k_t = 150 N m s (Fig. 4 speeds: ~1.7 deg/s under 10 N at grip gain 2) a 15 N hand takes
# ~15 s for the ~26 deg view changes of these scripts; 25 N does them in ~9 s.
HAND_FORCE = 25.0


def tissue_point(world: SimWorld, x: float, y: float) -> np.ndarray:
    """The tissue surface point (x, y) m from the one straight below the unloaded incision ({B}, m)."""
    return world.incision_rest_position() + np.array([x, y, -TISSUE_DEPTH])


def axis_toward(x: float, y: float) -> np.ndarray:
    """The unit shaft direction from the incision toward tissue point (x, y) (:func:`tissue_point`)."""
    v = np.array([x, y, -TISSUE_DEPTH])
    return v / np.linalg.norm(v)


def park_instrument(world: SimWorld, index: int) -> None:
    """An instrument withdrawn into its port: tip 2 cm inside the wall, out of the view."""
    world.set_instrument_tip(index, world.port_position(index) + np.array([0.0, 0.0, -0.02]))


def park_instruments(world: SimWorld) -> None:
    """Every instrument withdrawn into its port (:func:`park_instrument`)."""
    for i in range(world.n_instruments):
        park_instrument(world, i)


class Script(Protocol):
    """What the scenarios and the UI step: ``script(world, t)`` per tick (module docstring)."""

    # read-only: a class constant, an attribute or a property of the script
    @property
    def name(self) -> str: ...
    @property
    def duration(self) -> float: ...  # s of script time it runs for (inf: until :meth:`done`)
    @property
    def track_index(self) -> int: ...  # the instrument the camera is meant to follow
    @property
    def moves_instruments(self) -> bool: ...  # whether it places the instruments (the UI then leaves them alone)

    def __call__(self, world: SimWorld, t: float) -> float: ...

    def done(self, t: float) -> bool: ...


@dataclass
class ViewAdjustment:
    """Fig. 4: grip with ``grip_force`` (N) and turn the view ``angle_deg`` about the base's
    x + y diagonal (from where it points at the first call), then let go."""

    grip_force: float = 17.0
    angle_deg: float = 10.0
    variation: WorldVariation = field(default_factory=WorldVariation)
    name: ClassVar[str] = "view-adjustment"
    duration: ClassVar[float] = math.inf
    track_index: ClassVar[int] = 0
    moves_instruments: ClassVar[bool] = False
    hand: HandGuide | None = field(default=None, init=False, repr=False)

    def start(self, world: SimWorld) -> HandGuide:
        """The hand, aimed from where the view points now (the first call does this by itself)."""
        _, d0 = world.shaft_axis()
        self.hand = self.variation.hand(HandGuide(rotate_axis(d0, [1.0, 1.0, 0.0], self.angle_deg),
                                                  grip_force=self.grip_force))
        return self.hand

    def __call__(self, world: SimWorld, t: float) -> float:
        hand = self.start(world) if self.hand is None else self.hand
        return hand.apply(world, t, CONTROL_DT)

    def done(self, t: float) -> bool:
        """Once the view is within the hand's tolerance (the hand has let go)."""
        return self.hand is not None and not self.hand.engaged


@dataclass
class NeedleSearch:
    """Fig. 6-7 (module docstring): 26 s x ``time_scale``; the needle at ``needle`` (m, tissue)."""

    time_scale: float = 1.0
    variation: WorldVariation = field(default_factory=WorldVariation)
    needle: tuple[float, float] = (-0.035, 0.05)
    name: ClassVar[str] = "needle-search"
    track_index: ClassVar[int] = 0
    moves_instruments: ClassVar[bool] = True
    hand: HandGuide | None = field(default=None, init=False, repr=False)
    local: InstrumentPath | None = field(default=None, init=False, repr=False)
    fetch: InstrumentPath | None = field(default=None, init=False, repr=False)
    released_at: float | None = field(default=None, init=False)  # t7: the hand let go, the fetch starts

    @property
    def duration(self) -> float:
        return 26.0 * self.time_scale

    def done(self, t: float) -> bool:
        return t >= self.duration

    def _start(self, world: SimWorld) -> None:
        s, (nx, ny) = self.time_scale, self.needle
        self.hand = self.variation.hand(HandGuide(
            axis_toward(nx + 0.004, ny - 0.012), grip_force=24.0, max_force=HAND_FORCE, max_speed=0.25,
            tolerance_deg=1.5,
        ))
        origin = tissue_point(world, 0, 0)
        self.local = InstrumentPath(origin, [(0.012, -0.004), (0.0, 0.008), (0.014, 0.006), (0.01, -0.006)],
                                    speed=0.006 / s)
        self.fetch = InstrumentPath(origin, [(0.01, -0.006), (0.03, 0.01), (nx + 0.012, ny - 0.004)],
                                    speed=0.012 / s)
        park_instrument(world, 1)

    def __call__(self, world: SimWorld, t: float) -> float:
        if self.hand is None:
            self._start(world)
        assert self.hand is not None and self.local is not None and self.fetch is not None
        t7 = self.released_at
        world.set_instrument_tip(0, self.local.tip(t) if t7 is None else self.fetch.tip(t - t7))
        if t < 6.0 * self.time_scale:  # t0-t3: tracking only
            world.set_hand_wrench()  # hand off
            return 0.0
        grip_force = self.hand.apply(world, t, CONTROL_DT)
        if not self.hand.engaged and t7 is None:
            self.released_at = t
        return grip_force


@dataclass
class Workflow:
    """Fig. 9 (module docstring): 40 s x ``time_scale``."""

    time_scale: float = 1.0
    variation: WorldVariation = field(default_factory=WorldVariation)
    gauze1: tuple[float, float] = (0.05, 0.055)
    gauze2: tuple[float, float] = (-0.06, -0.05)
    organ: tuple[float, float] = (0.04, -0.03)
    name: ClassVar[str] = "workflow"
    track_index: ClassVar[int] = 0
    moves_instruments: ClassVar[bool] = True
    hands: tuple[HandGuide, HandGuide] | None = field(default=None, init=False, repr=False)
    tool: InstrumentPath | None = field(default=None, init=False, repr=False)

    @property
    def duration(self) -> float:
        return 40.0 * self.time_scale

    def done(self, t: float) -> bool:
        return t >= self.duration

    def _start(self, world: SimWorld) -> None:
        g1, g2, organ = self.gauze1, self.gauze2, self.organ
        h1, h2 = (self.variation.hand(HandGuide(axis_toward(*target), grip_force=30.0, max_force=HAND_FORCE,
                                                max_speed=0.25, tolerance_deg=1.5))
                  for target in (g1, organ))
        self.hands = (h1, h2)
        self.tool = InstrumentPath(
            tissue_point(world, 0, 0),
            [(0.02, 0.02), (g1[0] - 0.005, g1[1] - 0.01), (0.03, 0.02), (0.0, -0.01), (g2[0] + 0.01, g2[1] + 0.01),
             (0.0, -0.02), (organ[0] - 0.005, organ[1])],
            speed=0.01,
        )
        park_instrument(world, 1)

    def __call__(self, world: SimWorld, t: float) -> float:
        if self.hands is None:
            self._start(world)
        assert self.hands is not None and self.tool is not None
        s = self.time_scale
        world.set_instrument_tip(0, self.tool.tip(max(0.0, t - 3.0 * s) / s))
        h1, h2 = self.hands
        if t < 13.0 * s and h1.engaged:  # handle to the first gauze pad
            return h1.apply(world, t, CONTROL_DT)
        if 30.0 * s <= t and h2.engaged:  # handle toward the gallbladder
            return h2.apply(world, t, CONTROL_DT)
        world.set_hand_wrench()  # hand off: tracking
        return 0.0


SCRIPTS: dict[str, Callable[[float, WorldVariation], Script]] = {
    "needle-search": lambda time_scale, variation: NeedleSearch(time_scale, variation),
    "workflow": lambda time_scale, variation: Workflow(time_scale, variation),
}
"""The scenarios' scripts by scenario name: ``SCRIPTS[name](time_scale, variation)``."""
