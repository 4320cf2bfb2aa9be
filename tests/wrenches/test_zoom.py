"""The zoom cue (lapwrench.wrenches.zoom): insertion from the instruments' spread in the image."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lapwrench.config import ConfigError, from_dict
from lapwrench.rcm.geometry import TaskGeometry
from lapwrench.robot.model import Kinematics
from lapwrench.sensors import InstrumentObservation, ValidInputs
from lapwrench.wrenches.base import TickContext
from lapwrench.wrenches.registry import build_cues
from lapwrench.wrenches.zoom import ZoomCue, ZoomParams, in_band, instrument_spread, zoom_force

DIAG = math.hypot(640, 480)  # the default camera's image diagonal (px): 800
P = ZoomParams()
MID, HALF = 0.5 * (P.band[0] + P.band[1]), 0.5 * (P.band[1] - P.band[0])
DEAD = P.dead_zone * HALF  # no force within MID ± DEAD


DOWN = np.array([0.0, 0.0, -1.0])


def _context(points: np.ndarray | None, d_z: np.ndarray = DOWN) -> TickContext:
    """A tick context with the scope tip at (0.5, 0, 0.2), axis ``d_z`` and these image points."""
    n = 7
    z3, z6 = np.zeros(3), np.zeros((6, n))
    kin = Kinematics(np.zeros(n), np.zeros(n), np.eye(n), np.zeros(n), np.zeros(n), np.array([0.5, 0.0, 0.5]),
                     np.eye(3), z6, z3, np.eye(3), np.array([0.5, 0.0, 0.2]), np.eye(3), d_z,
                     np.eye(3) - np.outer(d_z, d_z), np.zeros(6))
    geo = TaskGeometry(z3, z3, z3, z3, np.zeros((3, n)), 0.0, np.array([0.5, 0.0, 0.25]), z3, z6, z3)
    obs = None if points is None else InstrumentObservation(np.asarray(points, float).reshape(-1, 2))
    return TickContext(0.0, kin, geo, ValidInputs(instruments=obs))


def _pair(spread: float) -> np.ndarray:
    """Two image points ``spread`` x the diagonal apart, around the image centre."""
    half = 0.5 * spread * DIAG
    return np.array([[320.0 - half, 240.0], [320.0 + half, 240.0]])


def _cue(**params: object) -> ZoomCue:
    cfg = from_dict({"cues": {"zoom": params}})
    return next(c for c in build_cues(cfg) if isinstance(c, ZoomCue))


def test_spread_is_the_widest_pair_over_the_image_diagonal() -> None:
    pts = np.array([[0.0, 0.0], [30.0, 40.0], [300.0, 400.0]])
    assert instrument_spread(pts, 640, 480) == pytest.approx(500.0 / DIAG)
    assert instrument_spread(pts[:2], 640, 480) == pytest.approx(50.0 / DIAG)


def test_spread_of_many_instruments_is_the_widest_of_all_pairs() -> None:
    pts = np.random.default_rng(3).uniform(0.0, 480.0, size=(6, 2))
    widest = max(float(np.linalg.norm(a - b)) for a in pts for b in pts)
    assert instrument_spread(pts, 640, 480) == pytest.approx(widest / DIAG, rel=1e-12)


@pytest.mark.parametrize("n", [0, 1])
def test_no_spread_with_fewer_than_two_instruments(n: int) -> None:
    assert math.isnan(instrument_spread(np.zeros((n, 2)), 640, 480))
    assert zoom_force(math.nan, P) == 0.0


def test_too_small_a_spread_pushes_in_too_large_pulls_out() -> None:
    assert zoom_force(0.1, P) > 0.0
    assert zoom_force(0.6, P) < 0.0


@pytest.mark.parametrize("x", [-0.99, -0.5, 0.0, 0.5, 0.99])
def test_no_force_in_the_dead_zone_around_the_middle(x: float) -> None:
    assert zoom_force(MID + x * DEAD, P) == 0.0


def test_force_grows_with_the_error_beyond_the_dead_zone_and_is_capped() -> None:
    small = 0.2 * P.F_max / P.gain  # well below the cap
    assert zoom_force(MID - DEAD - small, P) == pytest.approx(P.gain * small)
    assert zoom_force(MID - DEAD - 2 * small, P) == pytest.approx(2 * P.gain * small)
    assert zoom_force(MID + DEAD + small, P) == pytest.approx(-P.gain * small)
    assert zoom_force(0.0, P) == pytest.approx(P.F_max)
    assert zoom_force(1.0, P) == pytest.approx(-P.F_max)


def test_dead_zone_zero_acts_on_any_error_from_the_middle() -> None:
    p = ZoomParams(dead_zone=0.0)
    assert zoom_force(MID - 0.001, p) == pytest.approx(p.gain * 0.001)


def test_in_band_is_inclusive_and_false_for_no_spread() -> None:
    assert in_band(0.25, (0.25, 0.4)) and in_band(0.4, (0.25, 0.4)) and not in_band(0.41, (0.25, 0.4))
    assert not in_band(math.nan, (0.25, 0.4))


def test_the_cue_pushes_along_the_scope_axis_at_the_camera_point() -> None:
    cue = _cue()
    d_z = np.array([0.6, 0.0, -0.8])
    ctx = _context(_pair(0.15), d_z)
    w = cue.compute(ctx)
    assert np.allclose(w.point, ctx.kin.p_C) and not np.any(w.moment)
    assert np.allclose(w.force, P.F_max * d_z)  # far below the band: in, at the cap
    assert np.allclose(cue.compute(_context(_pair(0.7), d_z)).force, -P.F_max * d_z)


@pytest.mark.parametrize("points", [None, np.zeros((0, 2)), np.array([[100.0, 100.0]])])
def test_the_cue_gives_no_wrench_without_two_instruments(points: np.ndarray | None) -> None:
    cue = _cue()
    ctx = _context(points)
    w = cue.compute(ctx)
    assert not np.any(w.vector)
    spread, inside, force = cue.telemetry(ctx, w)
    assert math.isnan(spread) and math.isnan(inside) and force == 0.0


def test_telemetry_reports_the_spread_whether_it_is_in_the_band_and_the_force() -> None:
    cue = _cue(band=[0.2, 0.5])
    ctx = _context(_pair(0.3))
    spread, inside, force = cue.telemetry(ctx, cue.compute(ctx))
    assert spread == pytest.approx(0.3) and inside == 1.0 and force == 0.0
    ctx = _context(_pair(0.6))
    spread, inside, force = cue.telemetry(ctx, cue.compute(ctx))
    assert spread == pytest.approx(0.6) and inside == 0.0 and force < 0.0


def test_parameters_come_from_the_cues_section() -> None:
    cue = _cue(band=[0.1, 0.2], gain=10.0, F_max=2.0, dead_zone=0.0)
    assert cue.params == ZoomParams(band=(0.1, 0.2), dead_zone=0.0, gain=10.0, F_max=2.0)
    assert cue.inputs == ("instruments",) and cue.priority == "null"


@pytest.mark.parametrize(
    ("params", "where"),
    [
        ({"band": [0.4, 0.3]}, "band"),
        ({"band": [0.3]}, "cues.zoom.band"),
        ({"band": [0.0, 0.3]}, "cues.zoom.band[0]"),
        ({"band": [0.2, 1.5]}, "cues.zoom.band[1]"),
        ({"dead_zone": 1.0}, "cues.zoom.dead_zone"),
        ({"gain": 0}, "cues.zoom.gain"),
        ({"F_max": 50.0}, "cues.zoom.F_max"),
        ({"F_max": "strong"}, "cues.zoom.F_max"),
        ({"speed": 1.0}, "cues.zoom.speed"),
    ],
)
def test_bad_parameters_are_one_line_config_errors(params: dict, where: str) -> None:
    with pytest.raises(ConfigError) as err:
        from_dict({"cues": {"zoom": params}})
    assert "\n" not in str(err.value) and where in str(err.value)
