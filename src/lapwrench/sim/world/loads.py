"""The loads and props of :class:`~lapwrench.sim.world.SimWorld`: the surgeon's hand wrench on the
laparoscope, a sustained load on the phantom housing, and the instruments posed through their ports.

A mixin: the world builds the views of ``MjData`` and the ids it writes (listed below) at construction.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import ArrayLike

from lapwrench.sim.scene.instruments import instrument_pose_through_port
from lapwrench.spatial import all_finite

_NO_LOAD = (0.0, 0.0, 0.0)


def _three_finite(v: ArrayLike | None, name: str) -> tuple[float, ...]:
    """``v`` as three finite floats ((0, 0, 0) for None); ValueError naming the hand's ``name`` otherwise.
    A tuple of Python floats: called every control period, it must be cheap."""
    if v is None:
        return _NO_LOAD
    a = np.asarray(v, float)
    x = tuple(a.tolist()) if a.shape == (3,) else ()
    if len(x) != 3 or not (math.isfinite(x[0]) and math.isfinite(x[1]) and math.isfinite(x[2])):
        raise ValueError(f"hand {name} must be 3 finite numbers, got {v!r}")
    return x


class WorldLoads:
    """Hand wrench, housing load and instrument poses of a :class:`~lapwrench.sim.world.SimWorld`."""

    _body_H: int
    _body_housing: int
    _housing_k: float
    _mocap: list[int]
    _port_sites: list[int]
    _xfrc_applied: np.ndarray
    _site_xpos: np.ndarray
    _mocap_pos: np.ndarray
    _mocap_quat: np.ndarray

    def set_hand_wrench(self, *, force: ArrayLike | None = None, torque: ArrayLike | None = None) -> None:
        """Apply the surgeon's hand on the handle until changed: ``force`` (N) and ``torque`` (N m,
        about the lap_H origin), both in {B} (the base frame, which is MuJoCo's world frame here).
        An omitted (``None``) part is zero; no arguments take the hand off.

        Keyword-only, so the order cannot be mixed up: MuJoCo's ``xfrc_applied`` row is
        [force; torque], lapwrench's wrenches (:class:`~lapwrench.spatial.Wrench`) are [moment; force].
        """
        row = _three_finite(force, "force") + _three_finite(torque, "torque")
        # lap_H is massless, so its xfrc_applied acts at the lap_H origin.
        self._xfrc_applied[self._body_H] = row

    def hand_force(self) -> np.ndarray:
        """The hand force (N, {B}) currently applied at lap_H (:meth:`set_hand_wrench`)."""
        return self._xfrc_applied[self._body_H, :3].copy()

    def hand_torque(self) -> np.ndarray:
        """The hand torque (N m, {B}, about the lap_H origin) currently applied (:meth:`set_hand_wrench`)."""
        return self._xfrc_applied[self._body_H, 3:].copy()

    def set_housing_load(self, force: np.ndarray) -> None:
        """Sustained force (N, base frame) on the phantom housing (only x, y move it)."""
        f = np.asarray(force, float)
        if f.shape != (3,) or not all_finite(f):
            raise ValueError(f"housing load must be 3 finite numbers, got {force!r}")
        self._xfrc_applied[self._body_housing, :3] = f

    def housing_load_for_shift(self, shift: np.ndarray) -> np.ndarray:
        """Housing load (N) that shifts the phantom by ``shift`` (m, x/y) while the scope holds still.

        With the shaft held, the housing spring and the wall spring act in parallel.
        """
        sh = np.asarray(shift, float)
        return np.array([sh[0], sh[1], 0.0]) * self._housing_k

    @property
    def n_instruments(self) -> int:
        """Number of instruments in the scene (each with its own port)."""
        return len(self._mocap)

    def port_position(self, index: int) -> np.ndarray:
        """World position of instrument port ``index`` (0 left, 1 right); moves with the housing."""
        return self._site_xpos[self._port_sites[index]].copy()

    def set_instrument_pose(self, index: int, pos: np.ndarray, quat: np.ndarray) -> None:
        """Raw mocap pose of instrument ``index`` (origin at the jaw tip, quat wxyz)."""
        mid = self._mocap[index]
        self._mocap_pos[mid] = pos
        self._mocap_quat[mid] = quat

    def set_instrument_tip(self, index: int, tip: np.ndarray, roll: float = 0.0) -> None:
        """Put instrument ``index``'s jaw tip at ``tip`` with its shaft through its port."""
        pos, quat = instrument_pose_through_port(self.port_position(index), np.asarray(tip, float), roll)
        self.set_instrument_pose(index, pos, quat)

    def instrument_tip(self, index: int) -> np.ndarray:
        """Jaw tip position of instrument ``index`` (as last set; updated by the next step)."""
        return self._mocap_pos[self._mocap[index]].copy()
