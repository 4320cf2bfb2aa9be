"""The page's values are validated before they reach the simulation, and the hand's force model."""

from __future__ import annotations

import math

import numpy as np
import pytest

from lapwrench.sim.sensors import TactileGripModel
from lapwrench.ui.inputs import (
    GIZMO_STIFFNESS,
    GRIP_LEVELS,
    MAX_HAND_FORCE,
    HandInput,
    HandWrenchCache,
    UiInputError,
    checked_choice,
    checked_number,
    gizmo_force,
    grip_force_for_delta,
    push_force,
)


@pytest.mark.parametrize("bad", [float("nan"), float("inf"), -float("inf"), "3", None, True, [1.0], 1e300])
def test_checked_number_refuses_what_a_page_can_send(bad: object) -> None:
    with pytest.raises(UiInputError, match="push"):
        checked_number(bad, "push", 0.0, 30.0)


def test_checked_number_accepts_the_range_ends_and_numpy_scalars() -> None:
    assert checked_number(0, "x", 0.0, 1.0) == 0.0
    assert checked_number(np.float32(1.0), "x", 0.0, 1.0) == 1.0


def test_checked_choice_refuses_an_unknown_choice() -> None:
    assert checked_choice("high", "grip", tuple(GRIP_LEVELS)) == "high"
    with pytest.raises(UiInputError, match="unknown choice"):
        checked_choice("extreme", "grip", tuple(GRIP_LEVELS))


def test_grip_force_for_delta_gives_that_delta_on_the_simulated_handle() -> None:
    k_H = 2000.0
    force = grip_force_for_delta(1.5, k_H)
    tactile = TactileGripModel(seed=3)
    delta = np.mean([tactile.values(force).sum() / k_H for _ in range(200)])
    assert delta == pytest.approx(1.5, rel=0.03)


def test_push_force_is_across_the_shaft_with_the_asked_magnitude() -> None:
    d = np.array([0.1, 0.2, -0.97])
    d /= np.linalg.norm(d)
    for azimuth in (0.0, 45.0, 90.0, 200.0):
        f = push_force(d, azimuth, 12.0)
        assert abs(f @ d) < 1e-9
        assert np.linalg.norm(f) == pytest.approx(12.0)
    assert push_force(d, 0.0, 5.0) @ push_force(d, 90.0, 5.0) == pytest.approx(0.0, abs=1e-9)


def test_gizmo_force_is_a_capped_spring() -> None:
    np.testing.assert_allclose(gizmo_force(np.array([0.01, 0.0, 0.0])), [GIZMO_STIFFNESS * 0.01, 0.0, 0.0])
    far = gizmo_force(np.array([0.0, 5.0, 0.0]))
    assert np.linalg.norm(far) == pytest.approx(MAX_HAND_FORCE)
    assert np.all(gizmo_force(np.array([np.nan, 0.0, 0.0])) == 0.0)


def test_hand_input_caps_its_total_force_and_keeps_the_last_good_values() -> None:
    hand = HandInput()
    d = np.array([0.0, 0.0, -1.0])
    hand.set_push(30.0, 25.0)
    hand.set_gizmo([0.1, 0.0, 0.0])
    force, _torque = hand.wrench(d)
    assert np.linalg.norm(force) <= MAX_HAND_FORCE + 1e-9
    with pytest.raises(UiInputError):
        hand.set_push(float("nan"), 5.0)
    assert (hand.push_azimuth_deg, hand.push_magnitude) == (30.0, 0.0)  # a bad push value lets go of the push
    with pytest.raises(UiInputError):
        hand.set_gizmo("not a vector")
    assert np.all(hand.gizmo == 0.0)  # a bad drag lets go of the gizmo
    hand.set_twist(0.5)
    np.testing.assert_allclose(hand.wrench(d)[1], 0.5 * d)
    with pytest.raises(UiInputError):
        hand.set_twist(5.0)
    hand.set_grip_level("medium")
    assert hand.grip_force == GRIP_LEVELS["medium"]
    with pytest.raises(UiInputError):
        hand.set_grip_delta(math.inf, 2000.0)
    hand.release()
    assert hand.grip_force == hand.push_magnitude == hand.twist_torque == 0.0


def tilted_shaft() -> np.ndarray:
    d = np.array([0.3, -0.2, -0.93])
    return d / np.linalg.norm(d)


def test_the_gizmo_pulls_across_the_shaft_as_the_push_does() -> None:
    d = tilted_shaft()
    hand = HandInput()
    hand.set_gizmo(0.04 * d + np.array([0.03, 0.0, 0.0]))  # dragged along the shaft and across it
    force, _ = hand.wrench(d)
    assert abs(force @ d) < 1e-9, "no part of the pull along the shaft"
    spring = GIZMO_STIFFNESS * np.array([0.03, 0.0, 0.0])
    np.testing.assert_allclose(force, spring - (spring @ d) * d, atol=1e-9)  # the across part is kept whole
    hand.set_gizmo(0.05 * d)  # straight along the shaft: no push at all
    assert np.linalg.norm(hand.wrench(d)[0]) < 1e-9
    assert np.linalg.norm(hand.gizmo) == pytest.approx(GIZMO_STIFFNESS * 0.05)  # the spring itself is unchanged


def test_the_hand_wrench_cache_follows_the_hand_and_the_shaft() -> None:
    d = tilted_shaft()
    hand, cache = HandInput(), HandWrenchCache(turn=1e-3)
    hand.set_push(0.0, 10.0)
    f0, _, changed = cache.wrench(hand, d)
    assert changed
    np.testing.assert_array_equal(f0, hand.wrench(d)[0])
    assert not cache.wrench(hand, d + 1e-4)[2], "a shaft turn below the tolerance reuses the wrench"
    turned = d + np.array([0.0, 0.01, 0.0])
    turned /= np.linalg.norm(turned)
    f1, _, changed = cache.wrench(hand, turned)
    assert changed and abs(f1 @ turned) < 1e-9
    assert not cache.hand_changed, "a turned shaft is not a changed hand"
    hand.set_twist(0.4)
    _, torque, changed = cache.wrench(hand, turned)
    assert changed and cache.hand_changed
    np.testing.assert_allclose(torque, 0.4 * turned)
    hand.gizmo = np.array([5.0, 0.0, 0.0])  # even a field written directly counts
    assert cache.wrench(hand, turned)[2]
    assert cache.wrench(hand, turned, world=object())[2], "another world gets the hand again"


def test_a_bad_push_direction_never_keeps_the_last_push_on() -> None:
    """With a bad direction left on the page (NaN from a hostile page), lowering the magnitude to 0 was
    refused ('push direction (deg): must be a finite number, got nan') and the 12 N push stayed on."""
    hand = HandInput()
    hand.set_push(0.0, 12.0)
    for bad_azimuth, magnitude in ((float("nan"), 0.0), (float("nan"), 12.0), ("east", 5.0), (0.0, math.inf)):
        hand.set_push(0.0, 12.0)
        with pytest.raises(UiInputError):
            hand.set_push(bad_azimuth, magnitude)
        assert hand.push_magnitude == 0.0
        assert hand.push_azimuth_deg == 0.0  # the direction keeps its last good value
