"""The scenarios of the zoom and keep-out cues (lapwrench.sim.cue_scenarios) and their issue-13 targets."""

from __future__ import annotations

import pytest

from lapwrench.config import Config
from lapwrench.sim import cue_scenarios as cs
from lapwrench.sim.results import ScenarioOptions
from lapwrench.sim.world import SimWorld
from lapwrench.wrenches.keep_out import KeepOutParams
from lapwrench.wrenches.zoom import ZoomParams

PROJECTED = ScenarioOptions(detector="projected")


def test_the_separation_script_holds_its_values_and_blends_between_them() -> None:
    script = ((0.0, 0.03), (1.0, 0.03), (3.0, 0.05))
    assert cs.separation(0.5, script) == pytest.approx(0.03)
    assert cs.separation(2.0, script) == pytest.approx(0.04)
    assert cs.separation(9.0, script) == pytest.approx(0.05)


def test_every_keep_out_run_starts_outside_the_barrier_layer(cfg: Config, world: SimWorld) -> None:
    cases = cs.keep_out_cases(cfg, 1.0)
    assert [c.cue for c in cases] == [True, False, True, False]
    margin = KeepOutParams().margin
    for case in cases:
        assert case.distance(world) > margin  # the cue has nothing to do until the push drives the tip in


@pytest.mark.slow
def test_the_keep_out_cue_stops_a_20_newton_push_that_enters_the_zone_without_it(cfg: Config) -> None:
    res = cs.keep_out(cfg, PROJECTED)
    assert res.metrics["push_N"] == 20.0
    for run in res.runs:
        m = run.metrics
        if "with keep-out" in run.label:
            assert not m["entered_zone"] and m["distance_min_mm"] >= 0.0, run.label
            assert m["rcm_error_max_mm"] <= 2.0, run.label
        else:
            assert m["entered_zone"] and m["distance_min_mm"] < -2.0, run.label  # the cue is what holds it
    assert res.metrics["target_met"] and res.metrics["entered_without_cue"]


@pytest.mark.slow
def test_the_zoom_cue_keeps_the_spread_in_its_band_80_percent_of_the_tracking_time(cfg: Config) -> None:
    band = ZoomParams().band
    run = cs.zoom_run("with zoom", cfg.replace(cues={"zoom": {}}), PROJECTED, band)
    m = run.metrics
    assert m["tracking_time_s"] >= 8.0  # both instruments seen nearly all along
    assert m["in_band_fraction"] >= 0.8
    assert m["rcm_error_max_mm"] <= 2.0
    assert m["spread_min"] < band[0] or m["spread_max"] > band[1]  # the script does push it out of the band
