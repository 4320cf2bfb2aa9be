"""The tuning file (lapwrench.study.tune_spec): what it accepts, every refusal naming the key, and how a
constraint measures a breach."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lapwrench.study.spec import StudyError
from lapwrench.study.tune_spec import MAX_TRIALS, Constraint, from_dict, load_tune

PROP = settings(derandomize=True, database=None, deadline=None, max_examples=200)


def _tune(**over: Any) -> dict[str, Any]:
    data: dict[str, Any] = {"name": "fast", "scenarios": ["grip", "hard-push"], "seeds": [0],
                            "search": {"viscous.k_t": {"loguniform": [60, 300]}},
                            "objective": {"metric": "completion_time_s"}}
    data.update(over)
    return {k: v for k, v in data.items() if v is not ...}


def test_a_full_tuning_file_is_parsed() -> None:
    spec = from_dict(_tune(trials=16, time_scale=0.5, detector="projected",
                           search={"viscous.k_t": {"loguniform": [60, 300]}, "rcm.Kp": {"uniform": [200, 400]},
                                   "tracking.ramp": {"choice": ["printed", "c1"]}},
                           objective={"metric": "m.completion_time_s", "reduce": "max"},
                           constraints=[{"metric": "rcm_error_max_mm", "max": 1}, {"metric": "trocar_force_max_N",
                                                                                    "max": 5.0}]))
    assert spec.name == "fast" and spec.trials == 16
    assert spec.study.scenarios == ("grip", "hard-push") and spec.study.time_scale == 0.5
    assert spec.study.detector == "projected" and spec.study.grid == {}
    assert list(spec.search) == ["viscous.k_t", "rcm.Kp", "tracking.ramp"]
    assert spec.objective == "m.completion_time_s" and spec.reduce == "max"
    assert spec.constraints == (Constraint("m.rcm_error_max_mm", 1.0), Constraint("m.trocar_force_max_N", 5.0))


def test_defaults() -> None:
    spec = from_dict(_tune())
    assert spec.trials == 8 and spec.reduce == "mean" and spec.constraints == ()
    assert spec.objective == "m.completion_time_s"


@pytest.mark.parametrize(("data", "named"), [
    ("x", "mapping"),
    (_tune(grid={"viscous.k_t": [1]}), "'grid'"),
    (_tune(sample={}), "'sample'"),
    (_tune(scenarios=["nosuch"]), "nosuch"),
    (_tune(seeds=[-1]), "'seeds'"),
    (_tune(search=...), "'search'"),
    (_tune(search={}), "'search'"),
    (_tune(search=[1]), "'search'"),
    (_tune(search={"world.surgeon_force": {"uniform": [0.8, 1.2]}}), "world.surgeon_force"),
    (_tune(search={"world.nosuch": {"uniform": [0.8, 1.2]}}), "world.nosuch"),
    (_tune(search={"robot": {"choice": ["panda", "fr3"]}}), "robot"),
    (_tune(search={"viscous.k_t": [60, 300]}), "viscous.k_t"),
    (_tune(search={"viscous.k_t": {"uniform": [60, 1e9]}}), "viscous.k_t"),
    (_tune(search={"viscous.nosuch": {"uniform": [1, 2]}}), "viscous.nosuch"),
    (_tune(search={3: {"uniform": [1, 2]}}), "dotted names"),
    (_tune(objective=...), "'objective'"),
    (_tune(objective="completion_time_s"), "'objective'"),
    (_tune(objective={"reduce": "mean"}), "'objective'"),
    (_tune(objective={"metric": "x", "goal": "min"}), "'objective'"),
    (_tune(objective={"metric": "x", "reduce": "sum"}), "'objective.reduce'"),
    (_tune(objective={"metric": "x", "reduce": ["mean"]}), "'objective.reduce'"),
    (_tune(objective={"metric": ""}), "'objective.metric'"),
    (_tune(objective={"metric": 3}), "'objective.metric'"),
    (_tune(constraints={"metric": "x", "max": 1}), "'constraints'"),
    (_tune(constraints=[{"metric": "x"}]), "'constraints[0]'"),
    (_tune(constraints=[{"metric": "x", "max": 1}, {"metric": "y", "max": "1"}]), "'constraints[1]'"),
    (_tune(constraints=[{"metric": "x", "max": math.nan}]), "'constraints[0]'"),
    (_tune(constraints=[{"metric": "x", "max": math.inf}]), "'constraints[0]'"),
    (_tune(constraints=[{"metric": "x", "max": True}]), "'constraints[0]'"),
    (_tune(constraints=[{"metric": "x", "max": 1, "min": 0}]), "'constraints[0]'"),
    (_tune(constraints=[{"metric": "", "max": 1}]), "constraints[0].metric"),
    (_tune(constraints=["x"]), "'constraints[0]'"),
    (_tune(trials=0), "'trials'"),
    (_tune(trials=-3), "'trials'"),
    (_tune(trials=True), "'trials'"),
    (_tune(trials=4.0), "'trials'"),
    (_tune(trials="8"), "'trials'"),
    (_tune(trials=MAX_TRIALS + 1), "'trials'"),
    (_tune(trials=10**100), "'trials'"),
])
def test_refusals_name_the_key(data: Any, named: str) -> None:
    with pytest.raises(StudyError) as info:
        from_dict(data)
    assert named in str(info.value), str(info.value)


def test_trials_at_the_limit_are_fine() -> None:
    assert from_dict(_tune(trials=MAX_TRIALS)).trials == MAX_TRIALS
    assert from_dict(_tune(trials=1)).trials == 1


def test_robot_kind_is_refused_like_robot() -> None:
    with pytest.raises(StudyError, match="robot"):
        from_dict(_tune(search={"robot.kind": {"choice": ["panda", "fr3"]}}))


def test_load_tune_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "my-tune.yaml"
    path.write_text("scenarios: [grip]\nsearch:\n  viscous.k_t: {uniform: [60, 300]}\nobjective: {metric: x}\n"
                    "trials: 0\n")
    with pytest.raises(StudyError) as info:
        load_tune(str(path))
    assert "my-tune.yaml" in str(info.value) and "'trials'" in str(info.value)
    with pytest.raises(StudyError, match=r"my-tune\.yaml"):
        load_tune(str(tmp_path / "my-tune.yaml.missing"))
    path.write_bytes(b"\xff\xfe not utf-8")
    with pytest.raises(StudyError, match="tuning file"):
        load_tune(str(path))


def test_load_tune_reads_a_good_file(tmp_path: Path) -> None:
    path = tmp_path / "t.yaml"
    path.write_text("scenarios: [grip]\nsearch:\n  viscous.k_t: {uniform: [60, 300]}\n"
                    "objective: {metric: completion_time_s, reduce: median}\n")
    spec = load_tune(str(path))
    assert spec.name == "t" and spec.reduce == "median"


# --------------------------------------------------------------------------- Constraint.excess


def test_excess_is_zero_when_the_bound_holds() -> None:
    c = Constraint("m.rcm_error_max_mm", 1.0)
    assert c.excess(0.0) == 0.0 and c.excess(1.0) == 0.0 and c.excess(-math.inf) == 0.0


def test_excess_is_relative_to_the_bound() -> None:
    assert Constraint("m.x", 1.0).excess(1.5) == pytest.approx(0.5)
    assert Constraint("m.x", 5.0).excess(10.0) == pytest.approx(1.0)
    assert Constraint("m.x", -2.0).excess(-1.0) == pytest.approx(0.5)  # a negative bound: |max| in the ratio


def test_excess_of_nan_counts_as_one_and_inf_as_infinite() -> None:
    c = Constraint("m.x", 1.0)
    assert c.excess(math.nan) == 1.0
    assert c.excess(math.inf) == math.inf


def test_excess_with_a_zero_bound_is_finite_and_large() -> None:
    e = Constraint("m.x", 0.0).excess(1e-6)
    assert math.isfinite(e) and e > 100.0


@PROP
@given(bound=st.floats(-1e6, 1e6), a=st.floats(-1e7, 1e7), b=st.floats(-1e7, 1e7))
def test_excess_is_non_negative_and_monotone(bound: float, a: float, b: float) -> None:
    c = Constraint("m.x", bound)
    lo, hi = sorted((a, b))
    assert 0.0 <= c.excess(lo) <= c.excess(hi)
    assert (c.excess(a) == 0.0) == (a <= bound)


def test_a_search_normal_that_can_leave_the_keys_range_is_refused() -> None:
    """Ray Tune would drop such a trial halfway with a traceback; the file is refused instead."""
    with pytest.raises(StudyError, match=r"rcm\.Kp.*give it a min"):
        from_dict(_tune(search={"rcm.Kp": {"normal": [300, 1000]}}))
