"""Paper scenarios played on the page: a scripted surgeon (:mod:`lapwrench.sim.scripts`) stepped in
the live session, from the moment its button is pressed, with the page's own hand added on top.

The script moves the instruments (if it has any to move) and sets its hand on the world each tick;
:meth:`ScriptPlayer.apply` then adds the page's push, torque and gizmo pull to the script's hand and
grips with the firmer of the two grips, so the user can still push the handle while a scenario plays.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lapwrench.sim.scripts import SCRIPTS, Script, ViewAdjustment
from lapwrench.sim.variation import WorldVariation
from lapwrench.sim.world import SimWorld
from lapwrench.ui.inputs import checked_choice

PLAYABLE: dict[str, str] = {
    "view-adjustment": "Fig. 4: turn the view 10° at this grip",
    "needle-search": "Fig. 6-7: needle search (26 s)",
    "workflow": "Fig. 9: workflow (40 s)",
}
"""The scenarios the page plays, by name, with their buttons' labels."""
DEFAULT_GRIP = 17.0  # N, the Fig. 4 medium grip, when the page's hand does not grip


def make_script(name: object, grip_force: float = 0.0) -> Script:
    """The script of playable scenario ``name`` (:data:`PLAYABLE`) at full length; the Fig. 4 view
    adjustment grips with ``grip_force`` (N, :data:`DEFAULT_GRIP` if 0). UiInputError for another name."""
    key = checked_choice(name, "scenario", tuple(PLAYABLE))
    if key == "view-adjustment":
        return ViewAdjustment(grip_force=grip_force or DEFAULT_GRIP)
    return SCRIPTS[key](1.0, WorldVariation())


@dataclass
class ScriptPlayer:
    """``script`` played from session time ``t0`` (s)."""

    script: Script
    t0: float

    @property
    def name(self) -> str:
        return self.script.name

    def elapsed(self, t: float) -> float:
        """Script time (s) at session time ``t``."""
        return t - self.t0

    def apply(self, world: SimWorld, t: float, force: np.ndarray, torque: np.ndarray,
              grip: float) -> tuple[float, bool]:
        """One tick at session time ``t``: the script's move, then the page's hand (``force`` N,
        ``torque`` N m, {B}; ``grip`` N) added to the script's on the world.
        Returns (grip force N, whether the script has finished)."""
        s = self.elapsed(t)
        script_grip = self.script(world, s)
        world.set_hand_wrench(force=world.hand_force() + force, torque=world.hand_torque() + torque)
        return max(script_grip, grip), self.script.done(s)
