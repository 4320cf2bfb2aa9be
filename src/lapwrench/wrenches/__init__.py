"""Cues as wrenches: every cue becomes a wrench [moment; force] in {B} about a named point.

:class:`Cue` is the interface (:mod:`lapwrench.wrenches.base`); the paper's four cues are
registered like any plugin (:mod:`lapwrench.plugins`) and built from the ``cues:`` section by
:func:`~lapwrench.wrenches.registry.build_cues`.
"""

from lapwrench.wrenches.base import Cue, Priority, TickContext
from lapwrench.wrenches.interaction import InteractionCue
from lapwrench.wrenches.rcm import RcmCue
from lapwrench.wrenches.tracking import TrackingCue
from lapwrench.wrenches.viscous import ViscousCue

__all__ = ["Cue", "InteractionCue", "Priority", "RcmCue", "TickContext", "TrackingCue", "ViscousCue"]
