"""The scripted surgeon of the paper's scenarios, called tick by tick on a world that is not stepped."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lapwrench.sim.scripts import (
    SCRIPTS,
    TISSUE_DEPTH,
    NeedleSearch,
    ViewAdjustment,
    Workflow,
    axis_toward,
    tissue_point,
)
from lapwrench.sim.variation import WorldVariation
from lapwrench.sim.world import SimWorld


def test_the_axis_toward_a_tissue_point_is_a_unit_vector_pointing_at_it() -> None:
    a = axis_toward(0.03, -0.04)
    assert np.linalg.norm(a) == pytest.approx(1.0)
    assert a * (TISSUE_DEPTH / -a[2]) == pytest.approx([0.03, -0.04, -TISSUE_DEPTH])


def test_needle_search_tracks_first_then_the_hand_grips_and_pushes(world: SimWorld) -> None:
    script = NeedleSearch(time_scale=0.5)
    assert script.duration == pytest.approx(13.0) and script.moves_instruments
    assert script(world, 0.0) == 0.0  # t0-t3: tracking only, the hand off
    assert np.linalg.norm(world.hand_force()) == 0.0
    tip = world.instrument_tip(0)
    assert abs(tip[2] - tissue_point(world, 0.0, 0.0)[2]) < 1e-9  # on the tissue
    assert np.linalg.norm(tip - world.instrument_tip(1)) > 0.05  # the other one withdrawn
    grips = [script(world, 3.0 + k * 1e-3) for k in range(200)]  # t3 = 6 s x 0.5: the hand takes over
    assert grips[-1] == 24.0
    assert np.linalg.norm(world.hand_force()) > 0.0
    assert script.released_at is None
    assert not script.done(12.9) and script.done(13.0)


def test_the_workflow_hand_pushes_toward_the_first_gauze_then_lets_tracking_work(world: SimWorld) -> None:
    script = Workflow()
    assert script.duration == 40.0
    assert script(world, 0.0) == 30.0
    for k in range(1, 100):
        script(world, k * 1e-3)
    assert np.linalg.norm(world.hand_force()) > 0.0
    assert script(world, 20.0) == 0.0  # between the two hand phases
    assert np.linalg.norm(world.hand_force()) == 0.0


def test_the_surgeon_variation_scales_the_scripted_grip(world: SimWorld) -> None:
    script = SCRIPTS["workflow"](1.0, WorldVariation(surgeon_grip=0.5))
    assert script(world, 0.0) == pytest.approx(15.0)


def test_the_view_adjustment_turns_from_where_the_view_points_and_is_done_once_it_lets_go(world: SimWorld) -> None:
    script = ViewAdjustment(grip_force=5.0, angle_deg=10.0)
    assert not script.done(0.0) and math.isinf(script.duration)
    assert script(world, 0.0) == 5.0
    assert script.hand is not None
    assert math.degrees(script.hand.remaining(world)) == pytest.approx(10.0)
    script.hand.engaged = False
    assert script(world, 0.001) == 0.0 and script.done(0.001)
