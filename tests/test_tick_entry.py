"""The tick around the Python cues (lapwrench.tick_entry): the tick up to the cues written into one
buffer, its views, and the motion tail read back from it, against the stages they stand for."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.rcm.adaptive import AdaptiveState
from lapwrench.robot.model import KinematicTerms
from lapwrench.tick_core import SaturationInputs, motion_tail, tick_front
from lapwrench.tick_entry import front_into, front_size, front_views, motion_tail_from
from lapwrench.virtual import home_pose
from lapwrench.wrenches.ft_zero import FtTare


def test_the_views_are_disjoint_and_fill_the_buffer() -> None:
    n = 7
    buf = np.arange(front_size(n), dtype=np.float64)
    kin, geo = front_views(buf, n, 0.25)
    arrays = [*kin, *(a for name, a in zip(geo._fields, geo, strict=True) if name != "s_star")]
    values = np.sort(np.concatenate([np.ravel(a) for a in arrays]))
    np.testing.assert_array_equal(values, buf)  # every float once: disjoint, nothing left over
    assert geo.s_star == 0.25
    assert kin.M.shape == (n, n) and kin.J_E.shape == (6, n) and geo.J_R.shape == (3, n) and geo.J_G.shape == (6, n)
    kin.P[2, 1] = -1.0
    geo.e_R_offset[0] = -2.0
    assert np.count_nonzero(buf == -1.0) == 1 and np.count_nonzero(buf == -2.0) == 1  # views, not copies


def _state() -> tuple[Controller, KinematicTerms, np.ndarray, np.ndarray]:
    """A controller after reset, and a tick's arguments up to the cues at a moved pose (every input on)."""
    cfg = load()
    ctrl = Controller(cfg)
    ctrl.reset(home_pose(cfg.robot.kind))
    assert ctrl.ref is not None and ctrl.rcm is not None
    n = ctrl.ref.q.shape[0]
    q = ctrl.ref.q + 0.03 * np.sin(np.arange(n))
    R_m, p_m = (a.copy() for a in ctrl.model.placement_E_into(q + 0.002))
    terms = ctrl.model.terms(q, 0.1 * np.cos(np.arange(n)))
    return ctrl, terms, R_m, p_m


def _copies(state: AdaptiveState, offsets: np.ndarray) -> tuple[AdaptiveState, np.ndarray]:
    return AdaptiveState(*(a.copy() for a in state)), offsets.copy()


@pytest.mark.parametrize("has_ext", [True, False], ids=["with-residual", "without"])
def test_front_into_writes_what_tick_front_gives(has_ext: bool) -> None:
    ctrl, terms, R_m, p_m = _state()
    assert ctrl.rcm is not None
    force, ext = np.array([0.2, -0.1, 0.4]), np.array([7.0, 0.5, -0.2])  # a force inside the zero's band
    offsets = np.array([0.001, -0.002, 0.0, 0.003])
    rcm_a, off_a = _copies(ctrl.rcm.state, offsets)
    rcm_b, off_b = _copies(ctrl.rcm.state, offsets)
    args = (ctrl.rcm.params, ext, has_ext)
    torque, tactile = np.array([0.01, 0.0, -0.02]), np.zeros(64)
    tare_a, tare_b = FtTare.at(R_m), FtTare.at(R_m)
    reading = (R_m, p_m, True, force, torque, True, tactile, True)
    kin, geo, F_lat, residual, has_residual, hand_F, hand_T = tick_front(terms, rcm_a, *args, off_a, *reading, tare_a,
                                                                         ctrl.params)
    n = terms.q.shape[0]
    buf = np.full(front_size(n), np.nan)
    vec3, s_star, has = front_into(terms, rcm_b, *args, off_b, *reading, tare_b, ctrl.params, buf)
    assert has == has_residual == has_ext
    assert s_star == geo.s_star
    k, g = front_views(buf, n, s_star)
    for name, a, b in zip(kin._fields, kin, k, strict=True):
        np.testing.assert_array_equal(b, a, err_msg=name)
    for name, a, b in zip(geo._fields, geo, g, strict=True):
        np.testing.assert_array_equal(b, a, err_msg=name)
    np.testing.assert_array_equal(vec3, np.array([geo.e_R, geo.p_R, geo.p_G, F_lat, residual, hand_F, hand_T]))
    np.testing.assert_array_equal(tare_b.zero, tare_a.zero)  # stepped alike (untouched: it moves)
    assert np.any(tare_a.zero != 0.0)
    assert has_ext == bool(np.any(vec3[4] != 0.0))
    for name, a, b in zip(rcm_a._fields, rcm_a, rcm_b, strict=True):  # the state stepped alike
        np.testing.assert_array_equal(b, a, err_msg=name)
    np.testing.assert_array_equal(off_b, off_a)
    vec3[:] = 0.0
    assert np.isfinite(buf).all() and np.any(buf == geo.p_G[0])  # vec3 is its own array


def test_motion_tail_from_reads_back_what_front_into_wrote() -> None:
    ctrl, terms, R_m, p_m = _state()
    assert ctrl.rcm is not None
    n = terms.q.shape[0]
    buf = np.zeros(front_size(n))
    rcm, offsets = _copies(ctrl.rcm.state, np.zeros(4))
    _, s_star, _ = front_into(terms, rcm, ctrl.rcm.params, np.zeros(3), False, offsets, R_m, p_m, True,
                              np.array([1.0, 2.0, 3.0]), np.zeros(3), True, np.zeros(64), True, FtTare.at(R_m),
                              ctrl.params, buf)
    kin, geo = front_views(buf, n, s_star)
    sensors = (np.array([1.0, 2.0, 3.0]), np.array([0.1, 0.0, -0.1]), True, np.full(64, 62.5), True,
               np.array([[480.0, 300.0], [150.0, 200.0]]))
    extra = (np.array([[0.0, 0.1, 0.0, 1.0, -2.0, 3.0]]), np.array([[0.5, 0.0, 0.3]]), 0.5 * np.eye(6),
             np.array([0.0, 1.5, 0.0]))
    rest = (np.zeros(n), False, np.eye(3), 0.0, True)
    sat_a, sat_b = SaturationInputs.allocate(n), SaturationInputs.allocate(n)
    want = motion_tail(kin, geo, *sensors, *extra, *rest, sat_a, ctrl.params)
    got = motion_tail_from(buf, s_star, *sensors, *extra, *rest, sat_b, ctrl.params)
    assert len(got) == len(want)
    for a, b in zip(want, got, strict=True):
        np.testing.assert_array_equal(b, a)
    for a, b in zip(sat_a, sat_b, strict=True):
        np.testing.assert_array_equal(b, a)
    assert np.abs(want[0][4]).max() > 0.0  # the extra wrench reached W_n
