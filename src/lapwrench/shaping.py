"""The dead-zone / sine-ramp / saturation profile shared by eq (10) and eq (21)-(22).

Both printed profiles read

    f(x) = 0                                           x <= lo
           peak/2 * (sin((x - lo) pi / (2 (hi - lo))) + 1)   lo < x <= hi
           peak                                        x > hi

The text calls them smooth and continuous, but the printed middle branch starts at
``peak/2 (sin 0 + 1) = peak/2``: the profile jumps from 0 to half its maximum at ``lo``.

``variant="printed"`` implements the printed form (the default, as in the paper).
``variant="c1"`` is the fix the text describes: the phase runs from -pi/2 to pi/2,

    f(x) = peak/2 * (sin((x - lo) pi / (hi - lo) - pi/2) + 1),   lo < x <= hi

which is 0 with zero slope at ``lo`` and ``peak`` with zero slope at ``hi`` (continuously
differentiable everywhere).
"""

from __future__ import annotations

import math
from typing import Literal

from lapwrench.jit import kernel

RampVariant = Literal["printed", "c1"]


@kernel
def sine_ramp(x: float, lo: float, hi: float, peak: float, variant: RampVariant = "printed") -> float:
    """Dead zone below ``lo``, sine transition on (lo, hi], saturation at ``peak`` above ``hi``."""
    if x <= lo:
        return 0.0
    if x > hi:
        return peak
    if variant == "printed":
        return 0.5 * peak * (math.sin((x - lo) * math.pi / (2.0 * (hi - lo))) + 1.0)
    if variant == "c1":
        return 0.5 * peak * (math.sin((x - lo) * math.pi / (hi - lo) - 0.5 * math.pi) + 1.0)
    raise ValueError("unknown ramp variant; choose 'printed' or 'c1'")
