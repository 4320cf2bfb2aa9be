"""Finding cues and inputs by name: Python entry points, the way plugins register.

A cue (a class with ``compute(ctx) -> Wrench``, see :mod:`lapwrench.wrenches.base`) is registered
under the entry-point group :data:`CUE_GROUP`; an input (an
:class:`~lapwrench.sensors.InputSpec`: a named sensor reading a cue can ask for) under
:data:`INPUT_GROUP`. lapwrench registers its own the same way, in its ``pyproject.toml``::

    [project.entry-points."lapwrench.cues"]
    tracking = "lapwrench.wrenches.tracking:TrackingCue"

and a plugin package does the same in its own ``pyproject.toml``; ``pip install`` makes it
visible here, and its name can then appear in the ``cues:`` section of a configuration.

This module only looks names up and loads them; it imports nothing of lapwrench's, so the
configuration can check a ``cues:`` section as it loads (a plugin's own module, loaded here,
imports whatever it needs).
"""

from __future__ import annotations

import importlib.metadata
import re
from typing import Any

CUE_GROUP = "lapwrench.cues"
INPUT_GROUP = "lapwrench.inputs"
NAME = re.compile(r"[a-z][a-z0-9_]{0,39}\Z")  # \Z, not $: "a\n" is no name
"""What a cue or input name may look like: a lower-case identifier of at most 40 characters (it
becomes a log channel, a column and a YAML key)."""


class CueError(RuntimeError):
    """A cue failed, or returned something that is not what the :class:`~lapwrench.wrenches.base.Cue`
    interface promises; the message names the cue (in a run, the loop's alarm and a stop to rest; while
    the controller is built, one line from the CLI)."""


class PluginError(LookupError):
    """A cue or input name that is not registered, or whose entry point fails to load."""


def names(group: str) -> list[str]:
    """The names registered in ``group``, sorted."""
    return sorted({ep.name for ep in importlib.metadata.entry_points(group=group)})


def load(group: str, name: str) -> Any:
    """The object registered as ``name`` in ``group``.

    Raises :class:`PluginError` (one line) when the name is unknown, registered twice by different
    packages, or its module fails to import.
    """
    eps = [ep for ep in importlib.metadata.entry_points(group=group) if ep.name == name]
    kind = "cue" if group == CUE_GROUP else "input"
    if not eps:
        raise PluginError(f"no {kind} named {name!r} is installed; installed: {names(group)}")
    if len({ep.value for ep in eps}) > 1:
        raise PluginError(f"{kind} {name!r} is registered by more than one package: {sorted(ep.value for ep in eps)}")
    try:
        return eps[0].load()
    except (Exception, SystemExit) as exc:  # a plugin's import error is the user's to see, in one line (sys.exit too)
        detail = " ".join(str(exc).split())
        detail = detail if len(detail) <= 300 else detail[:297] + "..."
        raise PluginError(f"{kind} {name!r} ({eps[0].value}) failed to load: {type(exc).__name__}: {detail}") from exc
