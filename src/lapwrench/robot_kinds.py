"""The names of the arms lapwrench ships (:data:`ROBOT_KINDS`), below every other module.

The configuration (:mod:`lapwrench.config`) checks ``robot.kind`` against these names without
importing the robot layer above it; :mod:`lapwrench.robot.arms` registers one spec per name (a test
keeps the two equal). :data:`NOT_SHIPPED` names arms people ask for that are deliberately absent.
"""

from __future__ import annotations

ROBOT_KINDS: tuple[str, ...] = ("panda", "fr3", "ur5", "xarm7")
"""Every registered arm, in registry order (panda and fr3 also have a hardware driver)."""

_MENAGERIE = (
    "is not shipped: its model comes from mujoco-menagerie, whose PyPI package downloads the models from "
    "GitHub at run time; use {alt}, its example-robot-data stand-in"
)
NOT_SHIPPED: dict[str, str] = {
    "ur5e": _MENAGERIE.format(alt="ur5"),
    "gen3": _MENAGERIE.format(alt="xarm7"),
}
"""Arms that are asked for but not shipped, and why (one line each)."""


def unknown_kind_message(kind: str) -> str:
    """Why ``kind`` is not a shipped arm, in one line (its own reason for a :data:`NOT_SHIPPED` one)."""
    if kind in NOT_SHIPPED:
        return f"{kind} {NOT_SHIPPED[kind]}"
    return f"unknown robot {kind[:60]!r}; choose one of {', '.join(ROBOT_KINDS)}"
