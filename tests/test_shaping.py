"""The piecewise profiles of eq (10) and eq (21)-(22), printed and C1 variants."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.rcm.adaptive import dead_zone_saturation
from lapwrench.shaping import sine_ramp
from lapwrench.wrenches.tracking import TrackingParams, tracking_force_magnitude

LO, HI, PEAK = 50.0, 200.0, 10.0


@pytest.mark.parametrize("variant", ["printed", "c1"])
def test_dead_zone_and_saturation(variant: str) -> None:
    assert sine_ramp(0.0, LO, HI, PEAK, variant) == 0.0
    assert sine_ramp(LO - 1e-9, LO, HI, PEAK, variant) == 0.0
    assert sine_ramp(LO, LO, HI, PEAK, variant) == 0.0  # "0 <= d <= eps1" includes the threshold
    assert sine_ramp(HI, LO, HI, PEAK, variant) == pytest.approx(PEAK)
    assert sine_ramp(HI + 1e-9, LO, HI, PEAK, variant) == PEAK
    assert sine_ramp(1e6, LO, HI, PEAK, variant) == PEAK


def test_printed_form_jumps_to_half_at_the_inner_threshold() -> None:
    just_above = sine_ramp(LO + 1e-9, LO, HI, PEAK, "printed")
    assert just_above == pytest.approx(PEAK / 2, rel=1e-6)
    mid = 0.5 * (LO + HI)
    assert sine_ramp(mid, LO, HI, PEAK, "printed") == pytest.approx(PEAK / 2 * (math.sin(math.pi / 4) + 1))


def test_c1_form_is_continuous_with_zero_slope_at_both_ends() -> None:
    h = 1e-4
    assert sine_ramp(LO + h, LO, HI, PEAK, "c1") < 1e-6
    assert sine_ramp(HI - h, LO, HI, PEAK, "c1") > PEAK - 1e-6
    assert sine_ramp(0.5 * (LO + HI), LO, HI, PEAK, "c1") == pytest.approx(PEAK / 2)
    xs = [LO + i * (HI - LO) / 200 for i in range(201)]
    ys = [sine_ramp(x, LO, HI, PEAK, "c1") for x in xs]
    assert all(b >= a for a, b in itertools.pairwise(ys))
    assert max(abs(b - a) for a, b in itertools.pairwise(ys)) < PEAK * 0.01


def test_unknown_variant_is_rejected() -> None:
    with pytest.raises(ValueError, match="unknown ramp variant"):
        sine_ramp(100.0, LO, HI, PEAK, "cubic")  # type: ignore[arg-type]


def test_eq10_and_eq21_use_their_own_parameters() -> None:
    cfg = load()
    tracking = TrackingParams.from_config(cfg.camera, cfg.tracking)
    assert tracking_force_magnitude(50.0, tracking) == 0.0
    assert tracking_force_magnitude(201.0, tracking) == 10.0
    c1 = TrackingParams.from_config(cfg.camera, cfg.replace(tracking={"ramp": "c1"}).tracking)
    assert tracking_force_magnitude(50.001, c1) < 1e-3
    a = cfg.adaptive_rcm
    F = dead_zone_saturation(np.array([-20.0, 4.0, 10.0]), a.gamma1, a.gamma2, a.F_op, a.ramp)
    assert F[0] == -10.0 and F[1] == 0.0
    assert F[2] == pytest.approx(5.0 * (math.sin(math.pi / 4) + 1))
