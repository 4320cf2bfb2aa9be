"""Cues and an input registered for a test only: :func:`install` puts them in front of the real
entry points (``lapwrench.plugins.load``/``names``), the way an installed plugin package would."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pytest

from lapwrench import plugins
from lapwrench.config_ranges import ranged
from lapwrench.inputs import InputSpec
from lapwrench.spatial import Wrench
from lapwrench.wrenches.base import Cue, TickContext


@dataclass(frozen=True)
class SpringParams:
    target: tuple[float, float, float] = ranged("[-2, 2]", (0.45, 0.1, 0.3), "m in {B}")
    stiffness: float = ranged("(0, 500]", 40.0, "N/m")


class Spring(Cue):
    """A null-space spring pulling the camera point toward ``target``."""

    Params = SpringParams
    telemetry_fields = ("distance",)

    def compute(self, ctx: TickContext) -> Wrench:
        d = np.asarray(self.params.target) - ctx.kin.p_C
        return Wrench(np.zeros(3), self.params.stiffness * d, ctx.kin.p_C)

    def telemetry(self, ctx: TickContext, wrench: Wrench) -> tuple[float, ...]:
        return (float(np.linalg.norm(np.asarray(self.params.target) - ctx.kin.p_C)),)


class Sideways(Cue):
    """A task-space cue: a constant force at p_R."""

    priority = "task"

    def compute(self, ctx: TickContext) -> Wrench:
        return Wrench(np.zeros(3), np.array([3.0, 0.0, 0.0]), ctx.geometry.p_R)


class PedalHold(Cue):
    """Damps the camera point while a (registered) pedal input reads above 0.5."""

    inputs = ("pedal",)

    def compute(self, ctx: TickContext) -> Wrench:
        pedal = ctx.inputs.extra.get("pedal")
        if pedal is None or pedal.value[0] < 0.5:
            return Wrench.zero(ctx.kin.p_C)
        return Wrench(np.zeros(3), np.array([0.0, 0.0, -5.0]), ctx.kin.p_C)


class NotACue:
    name = "nope"


PEDAL = InputSpec("pedal", (1,), 0.0, 1.0, max_age=0.05, simulate=lambda world: (lambda t: [1.0 if t > 0.05 else 0.0]))
FAKE = {
    plugins.CUE_GROUP: {"spring": Spring, "sideways": Sideways, "pedal_hold": PedalHold, "nope": NotACue},
    plugins.INPUT_GROUP: {"pedal": PEDAL, "bad_input": NotACue},
}


def install(monkeypatch: pytest.MonkeyPatch) -> None:
    real_load, real_names = plugins.load, plugins.names

    def load(group: str, name: str) -> Any:
        return FAKE.get(group, {}).get(name) or real_load(group, name)

    def names(group: str) -> list[str]:
        return sorted(set(real_names(group)) | set(FAKE.get(group, {})))

    monkeypatch.setattr(plugins, "load", load)
    monkeypatch.setattr(plugins, "names", names)
