"""A lapwrench plugin in one file: a foot-pedal input and a cue that brings the view home while
the pedal is down.

- ``pedal`` (:data:`PEDAL`, entry point ``lapwrench.inputs``): one number in [0, 1], 1 = pressed.
  In simulation :func:`simulated_pedal` presses it on the :data:`PRESSED` schedule; on a robot
  (``lapwrench run``) :class:`PedalDriver` is its driver: replace its ``_read`` with your pedal's
  (a serial line, a USB HID device, a GPIO pin). lapwrench carries its value to the 1 kHz loop.
- ``pedal_home`` (:class:`PedalHomeCue`, entry point ``lapwrench.cues``): while the pedal reads
  above ``threshold``, a force at the scope tip p_C turns the scope axis toward the configured
  ``home`` direction; with the pedal up (or its reading missing or stale) the wrench is zero.

Registered in this package's ``pyproject.toml``; configured in the ``cues:`` section of a
lapwrench YAML (see ``pedal.yaml``).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from lapwrench.config_ranges import ranged
from lapwrench.inputs import InputSpec
from lapwrench.spatial import Vec, Wrench
from lapwrench.wrenches.base import Cue, TickContext

PRESSED = ((1.0, 3.0),)
"""Simulated schedule: (press, release) times in seconds of session time."""


def simulated_pedal(world: Any) -> Callable[[float], Vec]:
    """The simulated pedal: 1 inside a :data:`PRESSED` interval, else 0 (the world is not needed)."""

    def read(t: float) -> Vec:
        return np.array([1.0 if any(a <= t < b for a, b in PRESSED) else 0.0])

    return read


class PedalDriver:
    """The pedal's driver on a robot: a thread that reads the pedal at 100 Hz into ``buffer`` (the
    interface ``InputSpec.open`` returns: ``buffer``, ``close()``, and ``device`` for the start-up line).

    This example has no pedal to read: ``_read`` stands in for one, pressed 2 s out of every 4 s
    from when the driver starts. Replace it with your device's read.
    """

    device = "example pedal (pressed 2 s of every 4 s)"

    def __init__(self, cfg: Any) -> None:
        import threading

        from lapwrench.buffer import LatestValue

        self.buffer: LatestValue[Vec] = LatestValue("pedal")
        self._t0 = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="pedal", daemon=True)
        self._thread.start()

    def _read(self) -> Vec:
        t = (time.monotonic() - self._t0) % 4.0
        return np.array([1.0 if 1.0 <= t < 3.0 else 0.0])

    def _run(self) -> None:
        while not self._stop.wait(0.01):
            self.buffer.put(self._read())

    def close(self) -> None:
        self._stop.set()
        self._thread.join(1.0)


PEDAL = InputSpec(
    name="pedal", shape=(1,), lower=0.0, upper=1.0, max_age=0.1, update_interval=0.01,
    simulate=simulated_pedal, open=PedalDriver, doc="foot pedal, 0 = up, 1 = down",
)


@dataclass(frozen=True)
class PedalHomeParams:
    """Where home is and how hard the cue pulls (each range says why)."""

    home: tuple[float, float, float] = ranged("[-1, 1]", (0.0, 0.0, -1.0), "scope axis direction in {B}; normalised")
    gain: float = ranged("(0, 200]", 40.0, "N per rad of remaining angle")
    F_max: float = ranged("(0, 20]", 5.0, "N at the tip, half the tracking cue's F_max")
    threshold: float = ranged("(0, 1)", 0.5, "pedal reading above which it counts as pressed")


def home_force(d_z: Vec, home: Vec, gain: float, F_max: float) -> Vec:
    """F = min(F_max, gain θ) û, θ = ∠(d_z, home), û the unit part of home across the shaft: the tip
    moves toward where the home axis points (zero once the axis is home)."""
    across = home - (home @ d_z) * d_z
    n = float(np.linalg.norm(across))
    if n < 1e-9:
        return np.zeros(3)
    angle = math.acos(max(-1.0, min(1.0, float(home @ d_z))))
    return min(F_max, gain * angle) * across / n


class PedalHomeCue(Cue):
    """While the pedal is down, [0; F] about p_C with F = :func:`home_force` (module docstring)."""

    Params = PedalHomeParams
    inputs = ("pedal",)
    telemetry_fields = ("pressed", "angle_deg")

    def __init__(self, name: str, params: PedalHomeParams, cfg: Any) -> None:
        super().__init__(name, params, cfg)
        home = np.asarray(params.home, dtype=float)
        self.home = home / max(float(np.linalg.norm(home)), 1e-12)

    def pressed(self, ctx: TickContext) -> bool:
        """The pedal's reading is fresh and above the threshold."""
        r = ctx.inputs.extra.get("pedal")
        return r is not None and float(r.value[0]) > self.params.threshold

    def compute(self, ctx: TickContext) -> Wrench:
        if not self.pressed(ctx):
            return Wrench.zero(ctx.kin.p_C)
        F = home_force(ctx.kin.d_z, self.home, self.params.gain, self.params.F_max)
        return Wrench(np.zeros(3), F, ctx.kin.p_C)

    def telemetry(self, ctx: TickContext, wrench: Wrench) -> tuple[float, ...]:
        angle = math.degrees(math.acos(max(-1.0, min(1.0, float(self.home @ ctx.kin.d_z)))))
        return float(self.pressed(ctx)), angle
