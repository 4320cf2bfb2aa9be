"""Zoom: adjust the insertion so the tracked instruments keep a comfortable spread in the view (issue 13).

Camera-holder products and the dVRK autocamera move the scope in and out so the instruments
neither crowd the image centre nor leave it; the paper's tracking wrench (eq 8-12) only turns the
view. This cue adds the depth term: a force along the scope axis d_z at the camera point p_C
(+d_z points from the flange to the tip, into the body: moving in enlarges the scene).

The measure is the instruments' *spread*: the largest pixel distance between two detected
instruments, divided by the image diagonal (:func:`instrument_spread`). With fewer than two
instruments there is no spread, and the cue gives a zero wrench: a single point says nothing about
distance (the detector's box size would, but :class:`~lapwrench.sensors.InstrumentObservation`
carries points only), so depth is then left to the surgeon.

The force drives the spread toward the middle of the configured ``band``, with a dead zone around
the middle so the scope rests while the spread is comfortably inside (:func:`zoom_force`): the
spread then stays inside the band with margin instead of hovering at its edge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from lapwrench.config import Config
from lapwrench.config_ranges import ConfigError, ranged
from lapwrench.spatial import Vec, Wrench
from lapwrench.wrenches.base import Cue, TickContext


@dataclass(frozen=True)
class ZoomParams:
    """The spread band and how hard the cue pushes (module docstring)."""

    band: tuple[float, float] = ranged("(0, 1]", (0.25, 0.4), "spread / image diagonal: inside the image")
    dead_zone: float = ranged("[0, 1)", 0.4, "share of the band's half width, around its middle, without force")
    gain: float = ranged("(0, 1000]", 150.0, "N per unit of spread beyond the dead zone: F_max 0.05 beyond it")
    F_max: float = ranged("(0, 20]", 7.5, "N; against k_f = 150 N s/m, 7.5 N moves the scope at the envelope's 5 cm/s")

    def __post_init__(self) -> None:
        if not self.band[0] < self.band[1]:
            raise ConfigError(f"zoom: config key 'band' must be [low, high] with low < high, got {list(self.band)}",
                              "band")


def instrument_spread(points: Vec, width: float, height: float) -> float:
    """s = max_{i<j} ‖(u_i, v_i) - (u_j, v_j)‖ / √(width² + height²): the widest pair of detected
    instruments as a share of the image diagonal; NaN with fewer than two points."""
    if points.shape[0] < 2:
        return math.nan
    uv = points.tolist()  # a few detections: pairs of Python floats beat array broadcasting at 1 kHz
    widest = max(math.sqrt((u1 - u2) * (u1 - u2) + (v1 - v2) * (v1 - v2))
                 for i, (u1, v1) in enumerate(uv) for u2, v2 in uv[i + 1:])
    return widest / math.hypot(width, height)


def in_band(s: float, band: tuple[float, float]) -> bool:
    """low <= s <= high (False for NaN)."""
    return band[0] <= s <= band[1]


def zoom_force(s: float, p: ZoomParams) -> float:
    """Signed force (N) along +d_z (in): with m and h the band's middle and half width and
    e = m - s, F = sign(e) min(F_max, gain max(0, |e| - dead_zone h)); 0 for NaN.

    Too small a spread (e > 0) pushes in, too large pulls out."""
    if math.isnan(s):
        return 0.0
    mid, half = 0.5 * (p.band[0] + p.band[1]), 0.5 * (p.band[1] - p.band[0])
    e = mid - s
    return math.copysign(min(p.F_max, p.gain * max(0.0, abs(e) - p.dead_zone * half)), e)


class ZoomCue(Cue):
    """[0; F d_z] about the camera point p_C, F = :func:`zoom_force` of the instruments' spread.

    Inputs: the instrument detections. Telemetry: the spread (NaN with fewer than two
    instruments), whether it lies in the band (1/0; NaN without a spread) and the force (N, + in).
    """

    Params = ZoomParams
    inputs = ("instruments",)
    telemetry_fields = ("spread", "in_band", "force")

    def __init__(self, name: str, params: ZoomParams, cfg: Config) -> None:
        super().__init__(name, params, cfg)
        self._size = (float(cfg.camera.width), float(cfg.camera.height))
        self._last: tuple[TickContext | None, float] = (None, math.nan)  # this tick's spread, for telemetry


    def spread(self, ctx: TickContext) -> float:
        """The instruments' spread this tick (NaN without at least two detections)."""
        obs = ctx.inputs.instruments
        return math.nan if obs is None else instrument_spread(np.asarray(obs.points, float).reshape(-1, 2),
                                                              *self._size)

    def _tick_spread(self, ctx: TickContext) -> float:
        """:meth:`spread`, computed once a tick (``compute`` and ``telemetry`` see the same context)."""
        last, s = self._last
        if last is not ctx:
            s = self.spread(ctx)
            self._last = (ctx, s)
        return s

    def compute(self, ctx: TickContext) -> Wrench:
        F = zoom_force(self._tick_spread(ctx), self.params)
        return Wrench(np.zeros(3), F * ctx.kin.d_z, ctx.kin.p_C)

    def telemetry(self, ctx: TickContext, wrench: Wrench) -> tuple[float, ...]:
        s = self._tick_spread(ctx)
        band = math.nan if math.isnan(s) else float(in_band(s, self.params.band))
        return s, band, float(wrench.force @ ctx.kin.d_z)
