"""Wrench sources: every cue becomes a wrench [moment; force] in {B} about a named point."""

from lapwrench.wrenches.base import TaskGeometry, TickContext, WrenchSource
from lapwrench.wrenches.interaction import InteractionWrench
from lapwrench.wrenches.rcm import RcmWrench
from lapwrench.wrenches.tracking import TrackingWrench
from lapwrench.wrenches.viscous import ViscousWrench

__all__ = [
    "InteractionWrench",
    "RcmWrench",
    "TaskGeometry",
    "TickContext",
    "TrackingWrench",
    "ViscousWrench",
    "WrenchSource",
]
