"""Keep-out zone: a virtual fixture that keeps the scope tip out of a configured region (issue 13).

The zone is a sphere (``center``, ``radius``; e.g. around an organ) or a half-space (a ``point``
on its plane and the ``normal`` pointing *out* of the zone, toward the allowed side; e.g. below a
tissue surface). The tip (the camera point p_C) has a signed distance d to the zone, positive
outside. Inside a ``margin`` layer outside the zone (0 <= d < margin, and below, should the tip
ever get in) the cue pushes the tip out along the zone's outward normal n:

    F = min(F_max, k (margin - d)) n            a barrier spring, zero at the layer's outer edge
      - c (nᵀ v_C) n                            damping of the tip's normal velocity, in the layer

The damping is a linear viscous term, so it is also given as the damping matrix D about p_G
(:meth:`KeepOutCue.damping_matrix`) and the virtual model integrates it implicitly, like eq (40).

The cue acts in the null space: the RCM task keeps the pivot, so the tip can be stopped only by
turning the scope about the trocar or withdrawing it, both of which the null space does. Its
force must therefore outweigh the hand's push *as a moment about the pivot*: a push on the
handle, a lever arm l_H above the pivot, reaches the tip magnified by l_H / l_tip (about 3.3 on
the simulated scope at its start pose: 19 cm over 6 cm) and by the grip gain δ (~2 for a firm
grip): 20 N on the handle takes ~130 N at the tip, hence the large default cap.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from lapwrench.config_ranges import ConfigError, ranged
from lapwrench.spatial import Mat, Vec, Wrench, cross3, skew
from lapwrench.wrenches.base import Cue, TickContext


@dataclass(frozen=True)
class KeepOutParams:
    """The zone and the barrier (module docstring)."""

    shape: Literal["sphere", "plane"] = "sphere"
    center: tuple[float, float, float] = ranged("[-3, 3]", (0.5, 0.0, 0.1), "m in {B}: within an arm's reach")
    radius: float = ranged("(0, 0.5]", 0.03, "m: an organ, not the whole abdomen")
    point: tuple[float, float, float] = ranged("[-3, 3]", (0.5, 0.0, 0.1), "m in {B}: a point on the plane")
    normal: tuple[float, float, float] = ranged("[-1, 1]", (0.0, 0.0, 1.0), "out of the zone; normalised on use")
    margin: float = ranged("[0.001, 0.05]", 0.008, "m: the layer outside the zone where the barrier acts")
    stiffness: float = ranged("(0, 1e6]", 5e4, "N/m: 400 N over the default 8 mm margin; capped by F_max")
    F_max: float = ranged("(0, 1000]", 400.0, "N at the tip: must beat the hand's push times δ and the lever")
    damping: float = ranged("[0, 1e4]", 500.0, "N s/m on the tip's normal velocity inside the layer")

    def __post_init__(self) -> None:
        if self.shape == "plane" and math.hypot(*self.normal) < 1e-6:
            raise ConfigError(f"keep-out plane: config key 'normal' must not be the zero vector, "
                              f"got {list(self.normal)}", "normal")


def sphere_distance(p: Vec, center: Vec, radius: float) -> tuple[float, Vec]:
    """Signed distance of ``p`` to a ball, d = |p - c| - r (negative inside), and the outward unit
    normal (p - c)/|p - c| (+z when p sits at the centre, where any direction is as good)."""
    r = p - center
    n = float(np.linalg.norm(r))
    return n - radius, (r / n if n > 1e-12 else np.array([0.0, 0.0, 1.0]))


def plane_distance(p: Vec, point: Vec, normal: Vec) -> tuple[float, Vec]:
    """Signed distance of ``p`` to the half-space behind a plane, d = n̂ᵀ (p - p0) with n̂ the unit
    normal pointing out of the zone (negative inside), and n̂."""
    n = normal / np.linalg.norm(normal)
    return float(n @ (p - point)), n


def barrier_force(d: float, margin: float, stiffness: float, F_max: float) -> float:
    """Barrier magnitude (N): min(F_max, k (margin - d)) for d < margin, else 0."""
    return 0.0 if d >= margin else min(F_max, stiffness * (margin - d))


def tip_velocity_map(p_C: Vec, p_G: Vec) -> Mat:
    """A (3 x 6) with v_C = A [ω; v_G]: the velocity of p_C on the scope moving with twist [ω; v_G]
    about p_G, v_C = v_G + ω × (p_C - p_G). Its transpose moves a force at p_C to the wrench about
    p_G (eq 39)."""
    A = np.zeros((3, 6))
    A[:, :3] = -skew(p_C - p_G)
    A[:, 3:] = np.eye(3)
    return A


def normal_damping_matrix(n: Vec, c: float, A: Mat) -> Mat:
    """D = c Aᵀ n nᵀ A (6 x 6, about p_G): the wrench -D [ω; v_G] is -c (nᵀ v_C) n at p_C."""
    An = n @ A
    return c * np.outer(An, An)


class KeepOutCue(Cue):
    """The keep-out virtual fixture (module docstring), a null-space wrench about p_G.

    Inputs: none (the tip comes from the kinematics). Telemetry: the tip's signed distance to the
    zone (m, negative inside) and the barrier's magnitude (N).
    """

    Params = KeepOutParams
    telemetry_fields = ("distance", "barrier")

    def __init__(self, name: str, params: KeepOutParams, cfg: object) -> None:
        super().__init__(name, params, cfg)  # type: ignore[arg-type]
        p = params
        self._a = np.asarray(p.center if p.shape == "sphere" else p.point, dtype=float)
        self._normal = np.asarray(p.normal, dtype=float)
        self._last: tuple[TickContext | None, float, Vec, Mat | None] = (None, math.inf, self._normal, None)

    def distance(self, p: Vec) -> tuple[float, Vec]:
        """Signed distance of ``p`` to the zone (m, positive outside) and the outward normal."""
        if self.params.shape == "sphere":
            return sphere_distance(p, self._a, self.params.radius)
        return plane_distance(p, self._a, self._normal)

    def _tick(self, ctx: TickContext) -> tuple[float, Vec, Mat | None]:
        """The tip's distance and outward normal (:meth:`distance`) and the damping matrix (None outside
        the layer or without damping), computed once a tick: ``compute``, ``damping_matrix`` and
        ``telemetry`` all see the tick's same context."""
        last, d, n, D = self._last
        if last is not ctx:
            d, n = self.distance(ctx.kin.p_C)
            D = (None if d >= self.params.margin or self.params.damping == 0.0 else
                 normal_damping_matrix(n, self.params.damping, tip_velocity_map(ctx.kin.p_C, ctx.geometry.p_G)))
            self._last = (ctx, d, n, D)
        return d, n, D

    def damping_matrix(self, ctx: TickContext) -> Mat | None:
        return self._tick(ctx)[2]

    def compute(self, ctx: TickContext) -> Wrench:
        p_C, p_G = ctx.kin.p_C, ctx.geometry.p_G
        d, n, D = self._tick(ctx)
        if d >= self.params.margin:
            return Wrench.zero(p_G)
        spring = barrier_force(d, self.params.margin, self.params.stiffness, self.params.F_max)
        W = np.zeros(6)
        W[:3], W[3:] = cross3(p_C - p_G, spring * n), spring * n  # the barrier at p_C, about p_G (eq 39)
        if D is not None:
            W -= D @ (ctx.geometry.J_G @ ctx.kin.dq)
        return Wrench(W[:3], W[3:], p_G)

    def telemetry(self, ctx: TickContext, wrench: Wrench) -> tuple[float, ...]:
        d = self._tick(ctx)[0]
        return d, barrier_force(d, self.params.margin, self.params.stiffness, self.params.F_max)
