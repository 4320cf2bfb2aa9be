"""The grip's mass and centre of mass from F/T readings of the untouched handle (not in the paper).

The grip hangs beyond the handle's F/T sensor (:mod:`lapwrench.wrenches.grip_weight`); untouched, at a
rotation R_H of {H} in {B}, the sensor reads its weight on top of a constant bias b (after the tare):

    F = b_F + m u,    τ = b_τ + (m c) × u,    u = R_Hᵀ g,  g = (0, 0, -9.81) m/s² in {B}

in {H}, τ about the sensor's origin. Both are linear in the unknowns: [b_F, m] (4) from the forces,
[b_τ, m c] (6) from the torques ((m c) × u = -[u]× (m c)). :func:`fit_grip` solves them by least
squares on the samples centred on their means (which takes the biases out: the same solution as
the full systems) and c = (m c) / m. The weight is told from the bias only by how u changes: the
scope must have turned, untouched (:data:`MIN_TILT_DEG` between the gravity directions at least),
and the centre of mass needs u to change along two directions (:data:`MAX_CONDITION`).

Used by ``lapwrench identify-grip`` (:mod:`lapwrench.hardware.grip_identify`), which takes the samples
from a run's log.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from lapwrench.spatial import Vec
from lapwrench.wrenches.grip_weight import GRAVITY_B

MIN_SAMPLES = 100  # readings the fit needs at least
MIN_TILT_DEG = 10.0  # gravity directions in {H} must span this much (the weight against the bias)
# largest / smallest eigenvalue of the centre-of-mass normal matrix: beyond, u changed along one
# direction only and the centre of mass along it is not determined
MAX_CONDITION = 1e4
MAX_MASS = 2.0  # kg: the range of scope.grip_mass
MAX_COM = 0.2  # m per coordinate: the range of scope.grip_com
SPAN_POINTS = 1500  # directions compared pairwise for the tilt span (more are subsampled)
TILT_ADVICE = "tilt the scope by at least 10° (in two directions) while nobody touches the handle"


class GripFitError(ValueError):
    """The readings cannot give the grip's mass and centre of mass; the message says what to do."""


class GripFit(NamedTuple):
    """The fitted grip: ``mass`` (kg), ``com`` (m, in {H}), ``force_bias`` (N) and ``torque_bias`` (N m) of
    the tared sensor, the residual RMS of the force (N) and torque (N m) fits (the norm of the residual
    vector), the ``samples`` used, ``tilt_span_deg``, the largest angle between their gravity
    directions in {H}, and the standard errors of the mass (kg) and of each coordinate of the centre of
    mass (m) from the residuals. These assume independent readings: held samples (a sensor slower
    than the loop) or slow drifts make them optimistic."""

    mass: float
    com: Vec
    force_bias: Vec
    torque_bias: Vec
    force_rms: float
    torque_rms: float
    samples: int
    tilt_span_deg: float
    mass_sigma: float
    com_sigma: Vec


def gravity_in_H(R_H: np.ndarray) -> np.ndarray:
    """u = R_Hᵀ g for each rotation of ``R_H`` (N, 3, 3): gravity in {H}, (N, 3), m/s²."""
    return np.einsum("nki,k->ni", np.asarray(R_H, dtype=float), GRAVITY_B)


def tilt_span_deg(u: np.ndarray) -> float:
    """The largest angle (degrees) between the directions of the rows of ``u`` (N, 3; non-zero). Beyond
    :data:`SPAN_POINTS` rows, among the ones furthest from their mean direction and evenly spaced others."""
    d = np.asarray(u, dtype=float)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    if d.shape[0] > SPAN_POINTS:
        mean = d.mean(axis=0)
        far = np.argsort(d @ mean)[: SPAN_POINTS // 2]  # the least aligned with the mean
        spaced = np.linspace(0, d.shape[0] - 1, SPAN_POINTS - far.size).round().astype(int)
        d = d[np.unique(np.concatenate([far, spaced]))]
    return math.degrees(math.acos(float(np.clip((d @ d.T).min(), -1.0, 1.0))))


def skew_rows(v: np.ndarray) -> np.ndarray:
    """[v]× for each row of ``v`` (N, 3): (N, 3, 3), [v]× w = v × w."""
    s = np.zeros((v.shape[0], 3, 3))
    s[:, 0, 1], s[:, 0, 2] = -v[:, 2], v[:, 1]
    s[:, 1, 0], s[:, 1, 2] = v[:, 2], -v[:, 0]
    s[:, 2, 0], s[:, 2, 1] = -v[:, 1], v[:, 0]
    return s


def finite_rows(R_H: np.ndarray, force: np.ndarray, torque: np.ndarray) -> np.ndarray:
    """The samples whose rotation, force and torque are all finite (a boolean mask)."""
    return (
        np.isfinite(R_H).reshape(R_H.shape[0], -1).all(axis=1)
        & np.isfinite(force).all(axis=1)
        & np.isfinite(torque).all(axis=1)
    )


def _checked(R_H: object, force: object, torque: object) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    R = np.asarray(R_H, dtype=float)
    F = np.asarray(force, dtype=float)
    T = np.asarray(torque, dtype=float)
    n = R.shape[0] if R.ndim == 3 else -1
    if R.shape != (n, 3, 3) or F.shape != (n, 3) or T.shape != (n, 3):
        raise ValueError(f"expected rotations (N, 3, 3), forces and torques (N, 3), got {R.shape}, {F.shape}, "
                         f"{T.shape}")
    keep = finite_rows(R, F, T)
    return R[keep], F[keep], T[keep]


def fit_grip(R_H: object, force: object, torque: object) -> GripFit:
    """Least squares for the grip's mass and centre of mass from untouched readings (module docstring).

    ``R_H``: (N, 3, 3) rotations of {H} in {B}; ``force``, ``torque``: (N, 3) F/T readings in {H} (N, N m).
    Rows with a non-finite value are dropped. Raises :class:`GripFitError` for fewer than
    :data:`MIN_SAMPLES` rows, a tilt span under :data:`MIN_TILT_DEG`, gravity directions along one
    line only (:data:`MAX_CONDITION`), or a mass or centre of mass outside the configuration's ranges.
    """
    R, F, T = _checked(R_H, force, torque)
    n = R.shape[0]
    if n < MIN_SAMPLES:
        raise GripFitError(f"only {n} usable readings, the fit needs {MIN_SAMPLES}: record longer with the handle"
                           f" untouched and {TILT_ADVICE}")
    u = gravity_in_H(R)
    span = tilt_span_deg(u)
    if span < MIN_TILT_DEG:
        raise GripFitError(f"the scope turned only {span:.1f}° between the untouched readings, too little to tell"
                           f" the grip's weight from the sensor's bias: {TILT_ADVICE}")
    du = u - u.mean(axis=0)
    dF, dT = F - F.mean(axis=0), T - T.mean(axis=0)
    mass = float(np.sum(du * dF) / np.sum(du * du))  # F - F̄ = m (u - ū)
    force_bias = F.mean(axis=0) - mass * u.mean(axis=0)
    if mass <= 0.0:
        raise GripFitError(f"the fitted grip mass is {mass * 1e3:.1f} g: the F/T does not see a grip weight (with"
                           " nothing beyond the sensor, set scope.grip_mass: 0), or the handle was touched")
    A = -skew_rows(du)  # T - T̄ = -[u - ū]× (m c)
    normal = np.einsum("nki,nkj->ij", A, A)
    eig = np.linalg.eigvalsh(normal)
    if eig[0] <= eig[-1] / MAX_CONDITION:
        raise GripFitError(f"gravity changed along one direction only in {{H}} (the scope rested at two orientations"
                           f" or turned about one axis; tilt span {span:.1f}°): the centre of mass along it is not"
                           f" determined; {TILT_ADVICE}")
    mc = np.linalg.solve(normal, np.einsum("nki,nk->i", A, dT))
    torque_bias = T.mean(axis=0) - np.cross(mc, u.mean(axis=0))
    force_ss = float(np.sum((dF - mass * du) ** 2))
    torque_ss = float(np.sum((dT - np.einsum("nij,j->ni", A, mc)) ** 2))
    force_rms, torque_rms = math.sqrt(force_ss / n), math.sqrt(torque_ss / n)
    com = mc / mass
    mass_sigma = math.sqrt(force_ss / (3 * n - 4) / np.sum(du * du))
    mc_var = torque_ss / (3 * n - 6) * np.diag(np.linalg.inv(normal))
    com_sigma = np.sqrt(mc_var + (com * mass_sigma) ** 2) / mass  # c = (m c) / m, to first order
    if mass > MAX_MASS or np.abs(com).max() > MAX_COM:
        raise GripFitError(f"implausible fit: {mass * 1e3:.0f} g at {np.round(com * 1e3, 1).tolist()} mm in {{H}}"
                           f" (at most {MAX_MASS:g} kg within {MAX_COM:g} m): was the handle touched, or the arm"
                           f" moving? Force residual RMS {force_rms:.3g} N")
    return GripFit(mass, com, force_bias, torque_bias, force_rms, torque_rms, n, span, mass_sigma, com_sigma)
