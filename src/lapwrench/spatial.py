"""Spatial algebra shared by all wrench sources.

Conventions (paper Sec. III): a wrench is ``[moment; force]`` and a geometric Jacobian maps joint
rates to ``[angular velocity; linear velocity]``, both expressed in the base frame {B}. A wrench is
always attached to a reference point (the point its moment is taken about).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from lapwrench.jit import kernel

Vec = NDArray[np.float64]
Mat = NDArray[np.float64]


@kernel
def skew(v: Vec) -> Mat:
    """[v]x such that [v]x w = v x w."""
    S = np.zeros((3, 3))
    S[0, 1], S[0, 2] = -v[2], v[1]
    S[1, 0], S[1, 2] = v[2], -v[0]
    S[2, 0], S[2, 1] = -v[1], v[0]
    return S


@kernel
def wrench_transform(p_from: Vec, p_to: Vec) -> Mat:
    """Eq (39): Q moves a wrench taken about ``p_from`` to the equivalent wrench about ``p_to``.

        Q = [[I3, [p_from - p_to]x],
             [0,  I3             ]]

    so that M_to = M_from + (p_from - p_to) x F and F is unchanged, in the base frame.
    """
    Q = np.eye(6)
    Q[:3, 3:] = skew(p_from - p_to)
    return Q


@dataclass(frozen=True)
class Wrench:
    """A wrench ``[moment; force]`` in {B}, with the moment taken about ``point``."""

    moment: Vec
    force: Vec
    point: Vec

    @staticmethod
    def zero(point: Vec) -> Wrench:
        return Wrench(np.zeros(3), np.zeros(3), np.asarray(point, dtype=float))

    @property
    def vector(self) -> Vec:
        return np.concatenate([self.moment, self.force])

    def about(self, point: Vec) -> Vec:
        """The 6-vector of the same wrench taken about ``point`` (eq 39)."""
        return wrench_transform(self.point, point) @ self.vector
