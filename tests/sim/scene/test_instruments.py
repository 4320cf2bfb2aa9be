"""Instrument poses through their ports against the numpy formula."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from lapwrench.sim.scene.instruments import instrument_pose_through_port


def numpy_instrument_pose(port: np.ndarray, tip: np.ndarray, roll: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """The reference: :func:`instrument_pose_through_port` written with numpy's vector functions."""
    z = np.asarray(tip, float) - np.asarray(port, float)
    nz = np.linalg.norm(z)
    if nz < 1e-6:
        raise ValueError("instrument tip coincides with its port")
    z /= nz
    ref = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(ref, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = math.cos(roll), math.sin(roll)
    x, y = c * x + s * y, -s * x + c * y
    R = np.column_stack([x, y, z])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, R.ravel())
    return np.asarray(tip, float).copy(), quat


def test_instrument_pose_matches_the_numpy_formula_bit_for_bit() -> None:
    rng = np.random.default_rng(4)
    for i in range(2000):
        port = rng.normal(size=3) * 0.1
        step = rng.normal(size=3) if i % 3 else np.array([1e-3, -2e-3, -0.1])  # near-vertical shafts too
        tip = port + step * rng.uniform(0.002, 0.3)
        roll = rng.uniform(-3.0, 3.0) if i % 2 else 0.0
        pos, quat = instrument_pose_through_port(port, tip, roll)
        pos_ref, quat_ref = numpy_instrument_pose(port, tip, roll)
        np.testing.assert_array_equal(pos, pos_ref)
        np.testing.assert_array_equal(quat, quat_ref)
    with pytest.raises(ValueError, match="coincides"):
        instrument_pose_through_port(np.zeros(3), np.full(3, 1e-8))
