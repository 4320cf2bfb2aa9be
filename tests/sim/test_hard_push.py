"""The hard-push scenario (issue 9), shortened: durations scaled, physics unchanged.

Asserts what must hold whatever the tuning of the motion layer: no exception escapes (alarms and
simulation stops are results), every joint reference stays inside the Franka limits, every figure
of the table is finite. The issue's targets (RCM ≤ 2 mm, trocar force ≤ 10 N, depth range) are
reported, not asserted.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from lapwrench.config import Config, load
from lapwrench.sim import demo as demo_mod
from lapwrench.sim import hard_push as hp
from lapwrench.sim.results import ScenarioResult
from lapwrench.sim.scenarios import SCENARIOS, SIM_SECONDS, ScenarioOptions
from lapwrench.sim.world import SimWorld

pytestmark = pytest.mark.slow  # the hard-push runs in the MuJoCo world

TIME_SCALE = 0.3  # 0.45 s push + 0.3 s settling per run
TABLE_FIGURES = (
    "rcm_error_max_mm",
    "trocar_force_max_N",
    "tilt_max_deg",
    "depth_change_min_mm",
    "depth_change_max_mm",
    "delta_mean",
    "depth_rate_end_mm_s",
)


def test_the_full_set_covers_the_issue() -> None:
    cases = hp.default_cases()
    kinds = [c.kind for c in cases]
    assert kinds.count("lateral") == 12 and kinds.count("axial") == 12
    assert kinds.count("speed") == 3 and kinds.count("roll") == 1
    assert {c.magnitude for c in cases if c.kind in ("lateral", "axial")} == {10.0, 20.0, 30.0}
    assert {c.delta for c in cases if c.kind in ("lateral", "axial")} == {2.0, 1.1}
    assert {c.magnitude for c in cases if c.kind == "speed"} == {0.25, 0.5, 1.0}
    assert len({c.label for c in cases}) == len(cases)
    assert len(hp.ci_cases()) == 4
    assert SIM_SECONDS["hard-push"] == pytest.approx(hp.total_sim_seconds())
    assert "hard-push" in SCENARIOS


@pytest.mark.parametrize("case", [c for c in hp.default_cases() if c.kind != "speed" and c.magnitude != 20.0])
def test_pushes_keep_their_direction_relative_to_the_shaft(world: SimWorld, case: hp.PushCase) -> None:
    hand = hp.make_hand(case, world, push_s=1.0)
    assert hand.apply(world, 0.5, 1e-3) == case.grip_force
    f, tau = world.hand_force(), world.hand_torque()
    _, d = world.shaft_axis()
    if case.kind == "lateral":
        assert np.linalg.norm(f) == pytest.approx(case.magnitude) and abs(f @ d) < 1e-9
    elif case.kind == "axial":
        assert f @ d == pytest.approx(case.magnitude * case.axis[2])
    else:
        assert tau @ d == pytest.approx(case.magnitude) and np.linalg.norm(f) == 0.0
    full = _push_size(world)
    hand.apply(world, 0.0, 1e-3)
    assert _push_size(world) == pytest.approx(full / 50)  # rises over 50 ms
    hand.apply(world, 0.999, 1e-3)
    assert _push_size(world) == pytest.approx(full / 50)  # falls over 50 ms
    assert hand.apply(world, 1.0, 1e-3) == 0.0 and _push_size(world) == 0.0  # lets go


def _push_size(world: SimWorld) -> float:
    """|f| + |τ| of the hand (N, N m): the cases push with one of them only."""
    return float(np.linalg.norm(world.hand_force()) + np.linalg.norm(world.hand_torque()))


def test_shortened_hard_push_in_the_demo_report(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """30 N lateral, 30 N axial, the 1 rad/s hand and the roll torque, through ``lapwrench demo``."""
    results: dict = {}

    def reduced(cfg: Config, opts: ScenarioOptions) -> ScenarioResult:
        results["res"] = hp.hard_push(cfg, opts, cases=hp.ci_cases())
        return results["res"]

    monkeypatch.setitem(demo_mod.SCENARIOS, "hard-push", reduced)
    # one worker: the patched scenario table lives in this process only
    plan = demo_mod.plan_demo(tmp_path, ["hard-push"], time_scale=TIME_SCALE, video=False, workers=1)
    assert plan.configs["hard-push"] == load()  # the shipped defaults
    demo_mod.run_demo(plan, progress=False)  # no exception escapes: holds are rows of the table

    res = results["res"]
    assert [r.label for r in res.runs] == [c.label for c in hp.ci_cases()]
    for run in res.runs:
        m = run.metrics
        assert m["references_inside_limits"] is True, (run.label, m)
        for k in TABLE_FIGURES:
            if k == "depth_rate_end_mm_s" and m["alarm"] is not None:
                assert m[k] is None  # a run ended by a hold has no end-of-run rate
                continue
            assert m[k] is not None and math.isfinite(m[k]), (run.label, k, m[k])
        assert isinstance(m["envelope_hit_ticks"], int) and isinstance(m["envelope_walls"], str)
        assert m["alarm"] is None or isinstance(m["alarm"], str)
        assert isinstance(m["passed"], bool)
        assert m["depth_change_min_mm"] <= 0.0 <= m["depth_change_max_mm"]
        assert m["delta_mean"] == pytest.approx(2.0, abs=0.15)
        assert 0.0 < m["duration_s"] <= 0.75 + 1e-9
        print(
            f"{run.label:24s} RCM {m['rcm_error_max_mm']:6.2f} mm  F {m['trocar_force_max_N']:5.1f} N  "
            f"tilt {m['tilt_max_deg']:5.1f}°  "
            f"depth {m['depth_change_min_mm']:+6.1f}/{m['depth_change_max_mm']:+6.1f} mm  "
            f"end {m['depth_rate_end_mm_s'] or 0.0:+5.1f} mm/s  "
            f"hits {m['envelope_hit_ticks']} [{m['envelope_walls']}]  alarm {m['alarm']}  "
            f"{'pass' if m['passed'] else 'FAIL ' + str(m['failed_targets'])}"
        )
    assert res.metrics["all_references_inside_limits"] is True

    report = (tmp_path / "report.md").read_text()
    assert "## Hard pushes (issue 9)" in report and "hard_push.png" in report
    rows = [line for line in report.splitlines() if line.startswith("| ") and "δ2.0" in line]
    assert len(rows) == 4 and all(line.count("|") == 11 for line in rows)
    assert "≤ 2 mm" in report and "≤ 10 N" in report and "[30, 120] mm" in report
    assert (tmp_path / "hard_push.png").is_file()
    data = json.loads((tmp_path / "metrics.json").read_text())
    assert set(data["scenarios"]["hard-push"]["runs"]) == {c.label for c in hp.ci_cases()}
