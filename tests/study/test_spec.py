"""The study file (lapwrench.study.spec): every refusal is a StudyError naming the key (and the file), and
expand() gives a fixed, reproducible list of jobs whose run ids change with every input."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lapwrench import config as config_mod
from lapwrench.study.space import apply
from lapwrench.study.spec import MAX_JOBS, StudyError, StudySpec, expand, from_dict, load_study

PROP = settings(derandomize=True, database=None, deadline=None, max_examples=12)  # expand() costs ~0.1 s


def _study(**over: Any) -> dict[str, Any]:
    data: dict[str, Any] = {"name": "t", "scenarios": ["grip"], "seeds": 2}
    data.update(over)
    return {k: v for k, v in data.items() if v is not ...}


def _refused(data: Any, named: str) -> StudyError:
    with pytest.raises(StudyError) as info:
        from_dict(data)
    assert named in str(info.value), str(info.value)
    return info.value


# --------------------------------------------------------------------------- from_dict: accepted forms


def test_minimal_study_takes_defaults() -> None:
    spec = from_dict({"scenarios": ["grip"]}, "dir/my-study.yaml")
    assert spec.name == "my-study"  # from the file name
    assert spec.seeds == (0,) and spec.time_scale == 1.0 and spec.detector == "shipped"
    assert spec.grid == {} and spec.sample == {} and spec.n_jobs() == 1
    assert spec.report.metrics[0] == "m.completion_time_s"


@pytest.mark.parametrize(("seeds", "expected"), [
    (3, (0, 1, 2)),
    ([7, 0, 4], (7, 0, 4)),
    ({"start": 100, "count": 3}, (100, 101, 102)),
    ([2**32 - 1], (2**32 - 1,)),
])
def test_seed_forms(seeds: Any, expected: tuple[int, ...]) -> None:
    assert from_dict(_study(seeds=seeds)).seeds == expected


def test_report_metrics_get_the_m_prefix_and_keep_explicit_ones() -> None:
    spec = from_dict(_study(report={"metrics": ["rcm_error_max_mm", "s.target_met", "p.world.surgeon_force"],
                                    "pareto": None}))
    assert spec.report.metrics == ("m.rcm_error_max_mm", "s.target_met", "p.world.surgeon_force")
    assert spec.report.pareto is None


def test_report_params_are_the_grid_then_sample_keys() -> None:
    spec = from_dict(_study(grid={"viscous.k_t": [100, 200]}, sample={"world.surgeon_speed": {"uniform": [0.8, 1.2]}}))
    assert spec.params == ("viscous.k_t", "world.surgeon_speed")
    assert spec.report.params == spec.params


def test_compare_rows_are_parsed() -> None:
    spec = from_dict(_study(report={"compare": [
        {"label": "Fig. 4", "scenario": "grip", "run": "high", "metric": "completion_time_s", "paper": 6.32,
         "unit": "s"}]}))
    (c,) = spec.report.compare
    assert (c.scenario, c.run, c.metric, c.paper, c.unit) == ("grip", "high", "m.completion_time_s", 6.32, "s")


# --------------------------------------------------------------------------- from_dict: refusals


@pytest.mark.parametrize(("data", "named"), [
    ([1, 2], "mapping"),
    (None, "mapping"),
    (_study(grids={}), "'grids'"),
    (_study(name=""), "'name'"),
    (_study(name=3), "'name'"),
    (_study(scenarios=...), "'scenarios'"),
    (_study(scenarios=[]), "'scenarios'"),
    (_study(scenarios="grip"), "'scenarios'"),
    (_study(scenarios=["grip", "nosuch"]), "'nosuch'"),
    (_study(seeds=0), "'seeds'"),
    (_study(seeds=-3), "'seeds'"),
    (_study(seeds=True), "'seeds'"),
    (_study(seeds=2.0), "'seeds'"),
    (_study(seeds="3"), "'seeds'"),
    (_study(seeds=[]), "'seeds'"),
    (_study(seeds=[1, -1]), "'seeds'"),
    (_study(seeds=[2**32]), "'seeds'"),
    (_study(seeds=[True]), "'seeds'"),
    (_study(seeds=[1.0]), "'seeds'"),
    (_study(seeds=[3, 4, 3]), "'seeds'"),
    (_study(seeds={"start": 0}), "'seeds'"),
    (_study(seeds={"start": 0, "count": 2, "step": 1}), "'seeds'"),
    (_study(seeds={"start": -5, "count": 3}), "'seeds'"),
    (_study(seeds={"start": 0, "count": 0}), "'seeds'"),
    (_study(seeds={"start": 2**32 - 1, "count": 2}), "'seeds'"),
    (_study(seeds={"start": True, "count": 2}), "'seeds'"),
    (_study(seeds={"start": 0, "count": 1.5}), "'seeds'"),
    (_study(time_scale=0.01), "'time_scale'"),
    (_study(time_scale=1.5), "'time_scale'"),
    (_study(time_scale=0), "'time_scale'"),
    (_study(time_scale=float("nan")), "'time_scale'"),
    (_study(time_scale=True), "'time_scale'"),
    (_study(time_scale="0.5"), "'time_scale'"),
    (_study(detector="yolo"), "'detector'"),
    (_study(detector=3), "'detector'"),
    (_study(config=3), "'config'"),
    (_study(config="no-such-preset"), "'config'"),
    (_study(grid=[1, 2]), "'grid'"),
    (_study(sample="x"), "'sample'"),
    (_study(grid={"viscous.k_t": 100}), "viscous.k_t"),
    (_study(grid={"viscous.k_t": []}), "viscous.k_t"),
    (_study(grid={"viscous.k_t": [100, -1]}), "viscous.k_t"),
    (_study(grid={"viscous.nosuch": [1]}), "viscous.nosuch"),
    (_study(grid={"world.nosuch": [1]}), "nosuch"),
    (_study(grid={"world.detector_dropout": [0.5, 1.0]}), "world.detector_dropout"),
    (_study(grid={"robot": ["panda", "gen3"]}), "robot"),
    (_study(grid={3: [1]}), "dotted names"),
    (_study(sample={"world.surgeon_force": [0.8, 1.2]}), "world.surgeon_force"),
    (_study(sample={"world.surgeon_force": {"uniform": [0.0, 1.2]}}), "world.surgeon_force"),
    (_study(sample={"world.surgeon_force": {"normal": [1, 0.1], "min": -1}}), "world.surgeon_force"),
    (_study(sample={"viscous.k_t": {"uniform": [100, 1e9]}}), "viscous.k_t"),
    (_study(grid={"viscous.k_t": [100]}, sample={"viscous.k_t": {"uniform": [100, 200]}}), "viscous.k_t"),
    (_study(report=[1]), "'report'"),
    (_study(report={"metric": ["x"]}), "'report'"),
    (_study(report={"metrics": "rcm_error_max_mm"}), "'report.metrics'"),
    (_study(report={"metrics": [""]}), "'report.metrics'"),
    (_study(report={"metrics": [3]}), "'report.metrics'"),
    (_study(report={"pareto": ["a"]}), "'report.pareto'"),
    (_study(report={"pareto": "a"}), "'report.pareto'"),
    (_study(report={"pareto": ["a", None]}), "'report.pareto'"),
    (_study(report={"compare": {"label": "x"}}), "'report.compare'"),
    (_study(report={"compare": [{"label": "x", "scenario": "grip"}]}), "report.compare[0]"),
    (_study(report={"compare": [{"label": "x", "scenario": "grip", "metric": "m", "extra": 1}]}),
     "report.compare[0]"),
    (_study(report={"compare": [{"label": "x", "scenario": "nosuch", "metric": "m"}]}), "report.compare[0].scenario"),
    (_study(report={"compare": [{"label": "x", "scenario": "grip", "metric": "m", "paper": "6"}]}),
     "report.compare[0].paper"),
    (_study(report={"compare": [{"label": "x", "scenario": "grip", "metric": ""}]}), "report.compare[0]"),
])
def test_refusals_name_the_key(data: Any, named: str) -> None:
    _refused(data, named)


def test_unknown_top_key_lists_the_known_ones() -> None:
    exc = _refused(_study(seed=3), "'seed'")
    assert "seeds" in str(exc) and "scenarios" in str(exc)


@pytest.mark.parametrize("data", [
    pytest.param(_study(scenarios=[["grip"]])),
    pytest.param(_study(report={"compare": [{"label": "x", "scenario": ["grip"], "metric": "m"}]})),
    pytest.param({"scenarios": ["grip"], 1: 2, None: 3}),
])
def test_odd_yaml_types_are_a_study_error(data: Any) -> None:
    with pytest.raises(StudyError):
        from_dict(data)


def test_too_many_jobs_is_refused() -> None:
    exc = _refused(_study(scenarios=["grip", "zoom"], seeds=MAX_JOBS // 2 + 1), "more than")
    assert str(MAX_JOBS) in str(exc)
    assert from_dict(_study(seeds=MAX_JOBS)).n_jobs() == MAX_JOBS  # the limit itself is fine


def _overflow_grid() -> dict[str, list[float]]:
    """Every positive float key (and 4 world scales) with distinct valid values, 2**64 points in all."""
    defaults = config_mod.to_dict(config_mod.load(None))
    keys = [f"world.{f}" for f in ("surgeon_force", "surgeon_speed", "surgeon_grip", "trocar_stiffness")]
    keys += [f"{section}.{key}" for section, values in defaults.items() if section not in ("cues", "tactile", "camera")
             for key, value in values.items() if type(value) is float and value > 0]
    value = {k: 1.0 if k.startswith("world.") else defaults[k.split(".")[0]][k.split(".")[1]] for k in keys}
    n4 = 64 - len(keys)  # keys with 4 values, the rest with 2: 2**(len + n4) == 2**64
    return {k: [value[k] * (1 - 0.001 * i) for i in range(4 if j < n4 else 2)] for j, k in enumerate(keys)}


def test_overflow_grid_has_2_to_the_64_points() -> None:
    grid = _overflow_grid()
    assert math.prod(len(v) for v in grid.values()) == 2**64
    for end in (0, -1):  # each key's values span an interval; both ends are valid (all keys at once)
        apply(config_mod.load(None), {k: v[end] for k, v in grid.items()})


def test_grid_product_overflow_is_refused() -> None:
    with pytest.raises(StudyError, match="more than"):
        from_dict(_study(grid=_overflow_grid()))


def test_expanded_run_ids_are_unique() -> None:
    try:
        spec = from_dict(_study(grid={"viscous.k_t": [100, 100.0]}))
    except StudyError:
        return
    ids = [j.run_id for j in expand(spec)]
    assert len(ids) == len(set(ids))


@pytest.mark.parametrize("seeds", ["10**10", "{'start': 0, 'count': 10**10}"])
def test_seed_count_far_too_large_is_refused_without_exhausting_memory(seeds: str) -> None:
    """A huge seed count must be a StudyError, not a 10**10-tuple (run in a child capped at 3 GiB)."""
    code = ("import resource\nresource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))\n"
            "from lapwrench.study.spec import StudyError, from_dict\n"
            f"try:\n    from_dict({{'scenarios': ['grip'], 'seeds': {seeds}}})\n"
            "except StudyError as exc:\n    print('STUDYERROR', exc)\n")
    try:
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail("no answer in 60 s")
    out = proc.stdout + proc.stderr[-300:]
    assert "STUDYERROR" in out and ("seeds" in out or "more than" in out), out


# --------------------------------------------------------------------------- load_study: files


def test_load_study_reads_a_file(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("scenarios: [grip, zoom]\nseeds: {start: 5, count: 2}\ngrid:\n  viscous.k_t: [100, 200]\n")
    spec = load_study(path)
    assert spec.name == "s" and spec.n_jobs() == 8 and spec.seeds == (5, 6)


BAD_FILES: dict[str, bytes | None] = {
    "missing": None,
    "directory": b"",
    "latin1": "scenarios: [grip]\nname: caf\xe9\n".encode("latin-1"),
    "alias": b"a: &a [x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]\nscenarios: *b\n",
    "huge": b"scenarios: [grip]\n" + b"#" * (1 << 20) + b"\n",
    "tab": b"scenarios: [grip\n\tseeds: 3\n",
    "list": b"- grip\n- zoom\n",
    "badkey": b"scenarios: [grip]\ngrid:\n  viscous.k_t: [-5]\n",
    "duplicate": b"scenarios: [grip]\nseeds: 2\nseeds: 3\n",
    "tag": b"scenarios: !!python/object:os.system [grip]\n",
}


@pytest.mark.parametrize("case", list(BAD_FILES))
def test_load_study_refusals_name_the_file(tmp_path: Path, case: str) -> None:
    path = tmp_path / "bad-study.yaml"
    if case == "directory":
        path.mkdir()
    elif BAD_FILES[case] is not None:
        path.write_bytes(BAD_FILES[case])  # type: ignore[arg-type]
    with pytest.raises(StudyError) as info:
        load_study(path)
    text = str(info.value)
    assert "bad-study.yaml" in text and "\n" not in text and "config file" not in text, text
    assert case != "badkey" or "viscous.k_t" in text


# --------------------------------------------------------------------------- expand


SAMPLED = {"world.surgeon_force": {"normal": [1.0, 0.15], "min": 0.5, "max": 1.5},
           "world.surgeon_speed": {"uniform": [0.8, 1.25]},
           "interaction.k_min": {"choice": [2, 3, 4]},
           "viscous.k_f": {"loguniform": [50, 500]}}


def _sweep(**over: Any) -> StudySpec:
    return from_dict(_study(scenarios=["grip", "rcm-disturbance"], seeds=3,
                            grid={"viscous.k_t": [100, 200], "robot": ["panda", "fr3"]}, sample=SAMPLED, **over))


def test_expand_gives_scenarios_times_seeds_times_grid_points() -> None:
    spec = _sweep()
    jobs = expand(spec)
    assert len(jobs) == spec.n_jobs() == 2 * 3 * 4
    combos = {(j.scenario, j.seed, j.params["viscous.k_t"], j.params["robot"]) for j in jobs}
    assert len(combos) == len(jobs)
    assert len({j.run_id for j in jobs}) == len(jobs)


def test_expand_resolves_params_into_config_and_world() -> None:
    for j in expand(_sweep()):
        assert j.config["viscous"]["k_t"] == j.params["viscous.k_t"]
        assert j.config["robot"]["kind"] == j.params["robot"]
        assert j.config["viscous"]["k_f"] == j.params["viscous.k_f"]
        assert j.config["interaction"]["k_min"] == j.params["interaction.k_min"]
        assert j.world["surgeon_force"] == j.params["world.surgeon_force"]
        assert j.world["trocar_stiffness"] == 1.0
        assert 0.5 <= j.params["world.surgeon_force"] <= 1.5
        assert 0.8 <= j.params["world.surgeon_speed"] <= 1.25
        assert 50 <= j.params["viscous.k_f"] <= 500
        assert j.time_scale == 1.0 and j.detector == "shipped"


def test_expand_is_deterministic_with_16_hex_run_ids() -> None:
    a, b = expand(_sweep()), expand(_sweep())
    assert [(j.params, j.run_id) for j in a] == [(j.params, j.run_id) for j in b]
    assert all(len(j.run_id) == 16 and int(j.run_id, 16) >= 0 for j in a)


def test_every_scenario_of_a_seed_and_point_sees_the_same_draws() -> None:
    by_point: dict[tuple, set] = {}
    for j in expand(_sweep()):
        key = (j.seed, j.params["viscous.k_t"], j.params["robot"])
        by_point.setdefault(key, set()).add(tuple(sorted((k, j.params[k]) for k in SAMPLED)))
    assert all(len(draws) == 1 for draws in by_point.values())
    assert len({next(iter(d)) for d in by_point.values()}) == len(by_point)  # and differ between points


def test_draws_do_not_depend_on_the_scenario_list() -> None:
    one = {(j.seed, j.params["viscous.k_t"], j.params["robot"]): j.params
           for j in expand(from_dict(_study(scenarios=["zoom"], seeds=3,
                                            grid={"viscous.k_t": [100, 200], "robot": ["panda", "fr3"]},
                                            sample=SAMPLED)))}
    for j in expand(_sweep()):
        assert j.params == one[(j.seed, j.params["viscous.k_t"], j.params["robot"])]


def test_run_id_ignores_the_study_name_and_the_report() -> None:
    a = [j.run_id for j in expand(_sweep())]
    b = [j.run_id for j in expand(_sweep(name="other", report={"metrics": ["x"]}))]
    assert a == b  # the same run in another study file is the same run


def test_run_id_changes_with_every_input() -> None:
    job = expand(from_dict(_study(seeds=[5])))[0]
    base = job.run_id
    cfg = {**job.config, "viscous": {**job.config["viscous"], "k_t": 151.0}}
    variants = [
        dataclasses.replace(job, seed=6),
        dataclasses.replace(job, scenario="zoom"),
        dataclasses.replace(job, config=cfg),
        dataclasses.replace(job, world={**job.world, "surgeon_grip": 1.1}),
        dataclasses.replace(job, time_scale=0.5),
        dataclasses.replace(job, detector="classical"),
    ]
    ids = {v.run_id for v in variants}
    assert base not in ids and len(ids) == len(variants)


def test_run_id_changes_with_the_study_inputs() -> None:
    ref = expand(from_dict(_study(seeds=[5])))[0].run_id
    for over in ({"seeds": [6]}, {"time_scale": 0.5}, {"detector": "projected"},
                 {"grid": {"world.trocar_stiffness": [2.0]}}, {"grid": {"robot": ["fr3"]}},
                 {"grid": {"envelope.pivot_speed_max": [0.4]}}):
        assert expand(from_dict(_study(**{"seeds": [5], **over})))[0].run_id != ref, over


def test_params_equal_to_defaults_give_the_default_run_id() -> None:
    """A grid point that resolves to the base config is the same run as no grid at all (resume works)."""
    ref = expand(from_dict(_study(seeds=[5])))[0].run_id
    same = expand(from_dict(_study(seeds=[5], grid={"viscous.k_t": [150], "world.surgeon_force": [1]})))[0]
    assert same.run_id == ref


def test_an_unclipped_normal_that_can_leave_the_keys_range_is_refused_at_load() -> None:
    """A normal without min on a key that must stay > 0 could draw a refused value halfway through a
    sweep; it is refused when the file is loaded, with a hint to clip it."""
    for key, args in (("world.surgeon_force", [1.0, 2.0]), ("rcm.Kp", [300.0, 1000.0])):
        err = _refused(_study(seeds=30, sample={key: {"normal": args}}), key)
        assert "give it a min" in str(err)


def test_a_normal_clipped_inside_the_keys_range_is_accepted_and_its_draws_expand() -> None:
    spec = from_dict(_study(seeds=30, sample={"rcm.Kp": {"normal": [300.0, 1000.0], "min": 50.0, "max": 5000.0}}))
    assert all(50.0 <= j.params["rcm.Kp"] <= 5000.0 for j in expand(spec))


@pytest.mark.parametrize("name", ["../../etc/x", "a/b", "a\\b", "..", ".", "/abs", "x\0y"])
def test_a_name_that_is_not_a_plain_folder_name_is_refused(name: str) -> None:
    _refused(_study(name=name), "plain folder name")


def test_a_very_long_name_is_refused_in_a_short_line() -> None:
    err = _refused(_study(name="a" * 5000), "'name'")
    assert len(str(err)) < 200


def test_a_name_with_dots_inside_is_a_plain_folder_name() -> None:
    assert from_dict(_study(name=" v1..2 ")).name == "v1..2"


def test_a_corrupt_detector_model_is_refused_at_load(tmp_path: Path) -> None:
    """The model is loaded when the file is, as ``lapwrench demo --detector`` does, not by every run."""
    model = tmp_path / "garbage.onnx"
    model.write_bytes(bytes(range(256)) * 12)
    err = _refused(_study(detector=str(model)), "cannot be used")
    assert "garbage.onnx" in str(err) and "\n" not in str(err)
    _refused(_study(detector=str(tmp_path / "missing.onnx")), "missing.onnx")


@PROP
@given(lo=st.floats(0.1, 5.0), width=st.floats(0.01, 5.0), seeds=st.lists(st.integers(0, 2**32 - 1), min_size=1,
                                                                          max_size=4, unique=True))
def test_samples_respect_their_bounds_and_are_reproducible(lo: float, width: float, seeds: list[int]) -> None:
    data = _study(seeds=seeds, sample={"world.trocar_stiffness": {"uniform": [lo, lo + width]},
                                       "world.detector_noise_px": {"normal": [1.0, 3.0], "min": 0.0, "max": 2.0},
                                       "world.incision_shift_mm": {"integer": [1, 5]}})
    spec = from_dict(data)
    jobs = expand(spec)
    assert len(jobs) == len(seeds)
    for j in jobs:
        assert lo <= j.world["trocar_stiffness"] <= lo + width
        assert 0.0 <= j.world["detector_noise_px"] <= 2.0
        assert j.world["incision_shift_mm"] in (1.0, 2.0, 3.0, 4.0, 5.0)
    assert [j.run_id for j in expand(from_dict(data))] == [j.run_id for j in jobs]


@pytest.mark.parametrize("name", ["a\nb", "a\tb", "a\x1b[31mb", "a\rb"])
def test_a_name_with_a_line_break_or_control_character_is_refused(name: str) -> None:
    """Such a name became a results folder with a line break in it and broke the report's title line."""
    _refused(_study(name=name), "must be printable text")


def test_a_scenario_listed_twice_is_refused() -> None:
    """[grip, grip] gave every job twice under one run id: twice the rows, each counted twice in the report."""
    _refused(_study(scenarios=["grip", "rcm-disturbance", "grip"]), "'scenarios' lists a scenario twice")


def _example(module: Any) -> Any:
    """The YAML example of a module's docstring (the block after its ``::``)."""
    import textwrap

    import yaml

    block = module.__doc__.split("::", 1)[1].split("\n\n", 2)[1]
    return yaml.safe_load(textwrap.dedent(block))


def test_the_documented_examples_load() -> None:
    """The docstrings' examples swept interaction.k_t and rcm.K_p, keys the configuration does not have."""
    from lapwrench.study import spec, tune_spec

    assert set(from_dict(_example(spec)).grid) == {"viscous.k_t", "world.trocar_stiffness"}
    assert set(tune_spec.from_dict(_example(tune_spec)).search) == {"viscous.k_t", "rcm.Kp"}


def test_the_key_an_error_gives_as_an_example_is_a_key() -> None:
    """'parameter keys are dotted names such as interaction.k_t' named a key that is refused in turn."""
    err = _refused(_study(grid={"": [1]}), "parameter keys are dotted names such as ")
    example = str(err).split("such as ")[1].split(",")[0]
    assert from_dict(_study(grid={example: [100.0, 120.0]})).grid[example] == (100.0, 120.0)
