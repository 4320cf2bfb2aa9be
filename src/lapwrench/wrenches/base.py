"""The one interface every cue implements: :class:`Cue`.

A cue reads the tick's :class:`TickContext` (kinematics, the RCM and closest-point geometry, the
validated sensor inputs) and returns a :class:`~lapwrench.spatial.Wrench` in {B} about a point of
its choice. Null-space cues (the default) are moved to the closest point p_G with eq (39) and act
through J_G in the null space of the RCM task (eq 3-4, 37-38); task-space cues add their force to
the RCM force at p_R and act through J_R with the task's priority (eq 2).

To add a cue, write one class and register it (see :mod:`lapwrench.plugins`)::

    @dataclass(frozen=True)
    class Params:                      # validated from cues.<name> in the YAML
        stiffness: float = ranged("(0, 1000]", 50.0, "N/m")

    class Spring(Cue):
        Params = Params
        def compute(self, ctx):
            return Wrench(np.zeros(3), -self.params.stiffness * ctx.kin.p_C, ctx.kin.p_C)

    # pyproject.toml:  [project.entry-points."lapwrench.cues"]  spring = "mypkg:Spring"
    # config:          cues: {spring: {stiffness: 80}}

Its wrench then appears under its name in :attr:`TickResult.wrenches
<lapwrench.controller.TickResult.wrenches>`, the logs, the demo's traces and plots, and the live
telemetry, with no further code.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar, Literal

from lapwrench.config import Config
from lapwrench.plugins import CueError
from lapwrench.rcm.geometry import TaskGeometry
from lapwrench.robot.model import Kinematics
from lapwrench.sensors import ValidInputs
from lapwrench.spatial import Mat, Wrench

Priority = Literal["task", "null"]


@dataclass(frozen=True)
class TickContext:
    """What a cue reads: the tick's time (s), the kinematics at the reference, the task geometry
    (eq 27-36) and the inputs that passed validation (``inputs.extra`` holds registered inputs).

    The arrays of ``kin`` and ``geometry`` hold this tick's values only (the next tick overwrites
    them, :mod:`lapwrench.tick_entry`): a cue copies what it keeps."""

    time: float
    kin: Kinematics
    geometry: TaskGeometry
    inputs: ValidInputs


class Cue:
    """A cue turned into an equivalent wrench (the plugin interface; module docstring).

    Class attributes describe the kind of cue:

    - ``priority``: ``"null"`` (default) acts in the null space of the RCM task through the
      closest-point Jacobian; ``"task"`` adds its force at p_R to the RCM task (only its part
      lateral to the shaft acts).
    - ``inputs``: the readings it needs, by name: ``"ft"``, ``"tactile"``, ``"instruments"`` or a
      registered input (:data:`lapwrench.plugins.INPUT_GROUP`). A missing or stale input reaches
      ``compute`` as None; the cue must then return a zero wrench.
    - ``Params``: a frozen dataclass of :func:`~lapwrench.config_ranges.ranged` fields, built and
      range-checked from the cue's entry in the ``cues:`` section (None: no parameters).
    - ``config_section``: the paper's cues read their parameters from their own section of the
      configuration (``tracking:``, ...) instead.
    - ``fused``: computed inside the compiled tick (the paper's four cues): ``compute`` is then the
      reference the compiled tick is tested against, not what runs at 1 kHz.
    - ``telemetry_fields``: names of the numbers :meth:`telemetry` returns each tick (lower-case
      identifiers, at most :data:`~lapwrench.config_cues.MAX_CUE_TELEMETRY` a cue and
      :data:`~lapwrench.config_cues.MAX_TELEMETRY` for all the cues of a configuration, checked
      when it loads). They are logged every cycle: the traces' ``cue:<name>.<field>`` columns and
      the run log's ``telemetry.<name>.<field>`` (:mod:`lapwrench.hardware.log.telemetry`).
    """

    priority: ClassVar[Priority] = "null"
    inputs: ClassVar[tuple[str, ...]] = ()
    Params: ClassVar[type | None] = None
    config_section: ClassVar[str | None] = None
    fused: ClassVar[bool] = False
    telemetry_fields: ClassVar[tuple[str, ...]] = ()

    def __init__(self, name: str, params: Any, cfg: Config) -> None:
        self.name = name
        self.params = params
        self.cfg = cfg

    def compute(self, ctx: TickContext) -> Wrench:
        """The cue's wrench this tick, in {B}, about the point it names."""
        raise NotImplementedError(f"{type(self).__name__}.compute")

    def damping_matrix(self, ctx: TickContext) -> Mat | None:
        """D (6 x 6) when the wrench is -D J_G θ̇ about p_G (a viscous term): the integrator then treats
        it implicitly. None (default): the wrench is taken as it is. Its symmetric part must be positive
        semi-definite (damping takes energy out); another is dropped for the tick, with an event."""
        return None

    def telemetry(self, ctx: TickContext, wrench: Wrench) -> tuple[float, ...]:
        """One number per :attr:`telemetry_fields` entry, logged with the cue's wrench."""
        return ()

    def __repr__(self) -> str:
        return f"{type(self).__name__}({self.name!r})"


def call_cue(cue: Cue, method: str, *args: Any) -> Any:
    """``cue.<method>(*args)``; an exception from a plugin's code is a :class:`CueError` naming the cue and
    the method, the original chained (the alarm then says which plugin failed, not only what it raised)."""
    try:
        return getattr(cue, method)(*args)
    except CueError:
        raise
    except Exception as exc:
        raise CueError(f"cue {cue.name!r} {method}: {type(exc).__name__}: {exc}") from exc
