"""Parameter spaces (lapwrench.study.space): drawing and bounding each distribution, refusing malformed
ones, and routing a swept key to the config, a cue's parameters, the world or the robot."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from lapwrench import config as config_mod
from lapwrench.sim.variation import WorldVariation
from lapwrench.study.space import Dist, SpaceError, apply, check_dist, check_key, parse_dist

PROP = settings(derandomize=True, database=None, deadline=None, max_examples=60)
BASE = config_mod.load(None)


def _draws(dist: Dist, n: int = 2000, seed: int = 0) -> list:
    rng = np.random.default_rng(seed)
    return [dist.draw(rng) for _ in range(n)]


# --------------------------------------------------------------------------- draw / corners


def test_uniform_draws_lie_in_range_and_spread_over_it() -> None:
    d = parse_dist("k", {"uniform": [2, 5]})
    xs = _draws(d)
    assert all(isinstance(x, float) and 2.0 <= x < 5.0 for x in xs)
    assert min(xs) < 2.1 and max(xs) > 4.9
    assert d.corners() == (2.0, 5.0)


def test_loguniform_draws_lie_in_range_and_are_log_spread() -> None:
    d = parse_dist("k", {"loguniform": [1, 10000]})
    xs = np.array(_draws(d, 4000))
    assert np.all((xs >= 1.0) & (xs <= 10000.0))
    # a log-uniform draw has its median at the geometric mean (100), far below the midpoint
    assert 60.0 < float(np.median(xs)) < 160.0
    assert d.corners() == (1.0, 10000.0)


def test_normal_draws_are_clipped_to_min_and_max() -> None:
    d = parse_dist("k", {"normal": [1.0, 1.0], "min": 0.5, "max": 1.5})
    xs = np.array(_draws(d, 4000))
    assert xs.min() == 0.5 and xs.max() == 1.5  # wide sd: both clips are hit exactly
    assert abs(float(np.median(xs)) - 1.0) < 0.1
    assert set(d.corners()) == {0.5, 1.5, 1.0}


def test_normal_with_one_sided_clip() -> None:
    d = parse_dist("k", {"normal": [0.0, 1.0], "min": -0.25})
    xs = np.array(_draws(d))
    assert xs.min() == -0.25 and xs.max() > 1.0
    assert set(d.corners()) == {-0.25, 0.0}


def test_normal_without_clip_is_unbounded_around_the_mean() -> None:
    d = parse_dist("k", {"normal": [10.0, 2.0]})
    xs = np.array(_draws(d, 4000))
    assert abs(xs.mean() - 10.0) < 0.2 and abs(xs.std() - 2.0) < 0.2
    assert d.corners() == (10.0,)


def test_integer_includes_both_ends_and_only_them() -> None:
    d = parse_dist("k", {"integer": [3, 6]})
    xs = _draws(d)
    assert all(type(x) is int for x in xs)
    assert set(xs) == {3, 4, 5, 6}


def test_choice_draws_every_option_and_nothing_else() -> None:
    d = parse_dist("k", {"choice": ["panda", "fr3", 7]})
    xs = _draws(d, 300)
    assert set(xs) == {"panda", "fr3", 7}
    assert d.corners() == ("panda", "fr3", 7)


def test_single_choice_always_draws_it() -> None:
    assert set(_draws(parse_dist("k", {"choice": [0.25]}), 50)) == {0.25}


def test_draws_are_reproducible_from_the_generator_seed() -> None:
    for spec in ({"uniform": [0, 1]}, {"loguniform": [1, 2]}, {"normal": [0, 1]}, {"integer": [0, 99]},
                 {"choice": list("abcdef")}):
        d = parse_dist("k", spec)
        assert _draws(d, 20, seed=3) == _draws(d, 20, seed=3)
        assert _draws(d, 20, seed=3) != _draws(d, 20, seed=4)


@PROP
@given(lo=st.floats(-1e6, 1e6), width=st.floats(1e-3, 1e6), seed=st.integers(0, 2**32 - 1))
def test_uniform_draw_stays_within_its_corners(lo: float, width: float, seed: int) -> None:
    d = parse_dist("k", {"uniform": [lo, lo + width]})
    a, b = d.corners()
    x = d.draw(np.random.default_rng(seed))
    assert a <= x <= b


@PROP
@given(lo=st.floats(1e-6, 1e3), ratio=st.floats(1.001, 1e6), seed=st.integers(0, 2**32 - 1))
def test_loguniform_draw_stays_within_its_corners(lo: float, ratio: float, seed: int) -> None:
    d = parse_dist("k", {"loguniform": [lo, lo * ratio]})
    a, b = d.corners()
    x = d.draw(np.random.default_rng(seed))
    assert a * (1 - 1e-12) <= x <= b * (1 + 1e-12)


@PROP
@given(mean=st.floats(-100, 100), sd=st.floats(1e-3, 100), lo=st.floats(-50, 0), span=st.floats(1e-3, 100),
       seed=st.integers(0, 2**32 - 1))
def test_clipped_normal_draw_stays_within_min_and_max(mean: float, sd: float, lo: float, span: float,
                                                      seed: int) -> None:
    d = parse_dist("k", {"normal": [mean, sd], "min": lo, "max": lo + span})
    x = d.draw(np.random.default_rng(seed))
    assert lo <= x <= lo + span


@PROP
@given(lo=st.integers(-1000, 1000), width=st.integers(1, 1000), seed=st.integers(0, 2**32 - 1))
def test_integer_draw_is_a_whole_number_in_the_closed_range(lo: int, width: int, seed: int) -> None:
    x = parse_dist("k", {"integer": [lo, lo + width]}).draw(np.random.default_rng(seed))
    assert type(x) is int and lo <= x <= lo + width


# --------------------------------------------------------------------------- parse_dist refusals


@pytest.mark.parametrize("spec", [
    [0.8, 1.2], "uniform", 3, None,  # not a mapping
    {"uniform": [0, 1], "normal": [0, 1]},  # two kinds
    {},  # no kind
    {"uniform": [0, 1], "step": 0.1},  # unknown extra key
    {"gaussian": [0, 1]},  # unknown kind
    {"uniform": [0]}, {"uniform": [0, 1, 2]}, {"uniform": []}, {"uniform": 1.0}, {"uniform": {"a": 1}},
    {"choice": []}, {"choice": "abc"},
    {"uniform": [0, float("nan")]}, {"uniform": [float("-inf"), 1]}, {"normal": [0, float("inf")]},
    {"uniform": [True, 2]}, {"integer": [0, False]}, {"uniform": ["0", 1]}, {"uniform": [None, 1]},
    {"uniform": [1, 1]}, {"uniform": [2, 1]}, {"integer": [5, 5]}, {"loguniform": [3, 2]},
    {"loguniform": [0, 1]}, {"loguniform": [-1, 1]},
    {"integer": [0.5, 3]}, {"integer": [0, 2.5]},
    {"normal": [0, 0]}, {"normal": [0, -1]},
    {"normal": [0, 1], "min": 1, "max": 1}, {"normal": [0, 1], "min": 2, "max": 1},
    {"normal": [0, 1], "min": float("nan")}, {"normal": [0, 1], "max": True}, {"normal": [0, 1], "min": "0"},
    {"uniform": [0, 1], "min": 0}, {"loguniform": [1, 2], "max": 2}, {"integer": [0, 5], "min": 1},
])
def test_parse_dist_refuses_with_the_key_named(spec: object) -> None:
    with pytest.raises(SpaceError, match=r"world\.surgeon_force"):
        parse_dist("world.surgeon_force", spec)


def test_min_max_are_refused_on_choice_too() -> None:
    with pytest.raises(SpaceError, match="k"):
        parse_dist("k", {"choice": [1, 2], "min": 0})


def test_dist_with_keys_of_mixed_types_is_a_space_error() -> None:
    with pytest.raises(SpaceError, match="k"):
        parse_dist("k", {"uniform": [0, 1], 1: 2, None: 3})


def test_parse_dist_never_raises_anything_but_space_error() -> None:
    @PROP
    @given(spec=st.recursive(
        st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=5),
        lambda inner: st.lists(inner, max_size=4) | st.dictionaries(
            st.sampled_from(["uniform", "loguniform", "normal", "integer", "choice", "min", "max", "x"]),
            inner, max_size=3),
        max_leaves=8))
    def prop(spec: object) -> None:
        try:
            d = parse_dist("key.x", spec)
        except SpaceError as exc:
            assert "key.x" in str(exc)
            return
        d.draw(np.random.default_rng(0))  # an accepted dist can always draw
        assert d.corners()

    prop()


# --------------------------------------------------------------------------- apply routing


def test_apply_routes_a_config_key() -> None:
    cfg, world = apply(BASE, {"viscous.k_t": 90.0, "envelope.pivot_speed_max": 0.3})
    assert cfg.viscous.k_t == 90.0 and cfg.envelope.pivot_speed_max == 0.3
    assert cfg.viscous.k_f == BASE.viscous.k_f  # the rest untouched
    assert world == WorldVariation()


def test_apply_does_not_mutate_the_base() -> None:
    before = config_mod.to_dict(BASE)
    apply(BASE, {"viscous.k_t": 90.0, "robot": "fr3"})
    assert config_mod.to_dict(BASE) == before


def test_apply_routes_world_fields_and_robot() -> None:
    cfg, world = apply(BASE, {"world.surgeon_force": 1.3, "world.detector_dropout": 0.2, "robot": "fr3"})
    assert world.surgeon_force == 1.3 and world.detector_dropout == 0.2
    assert world.trocar_stiffness == 1.0
    assert cfg.robot.kind == "fr3"


def test_robot_key_and_robot_kind_are_the_same() -> None:
    assert apply(BASE, {"robot": "ur5"})[0] == apply(BASE, {"robot.kind": "ur5"})[0]


def test_apply_routes_a_cue_parameter(tmp_path: Path) -> None:
    path = tmp_path / "keep.yaml"
    path.write_text("cues:\n  keep_out:\n    radius: 0.04\n")
    base = config_mod.load(path)
    cfg, _ = apply(base, {"cues.keep_out.radius": 0.02})
    entry = cfg.cue("keep_out")
    assert entry is not None and entry.params.radius == 0.02
    cfg, _ = apply(base, {"cues.keep_out.center": (0.4, 0.0, 0.1)})  # a tuple, as from a choice
    assert tuple(cfg.cue("keep_out").params.center) == (0.4, 0.0, 0.1)
    with pytest.raises(SpaceError, match=r"cues\.keep_out\.radius"):
        apply(base, {"cues.keep_out.radius": -1.0})
    with pytest.raises(SpaceError, match=r"cues\.keep_out\.nope"):
        apply(base, {"cues.keep_out.nope": 1.0})


@pytest.mark.parametrize(("params", "named"), [
    ({"nosuch.k_t": 1.0}, "nosuch"),  # unknown section
    ({"viscous.nosuch": 1.0}, r"viscous\.nosuch"),  # unknown key
    ({"viscous": 1.0}, "viscous"),  # a whole section
    ({"viscous.k_t.deeper": 1.0}, r"viscous\.k_t\.deeper"),
    ({"cues": 1.0}, "cues"),
    ({"viscous.k_t": -1.0}, r"viscous\.k_t"),  # refused by the config's range
    ({"viscous.k_t": "fast"}, r"viscous\.k_t"),
    ({"robot": "ur5e"}, r"robot\.kind"),  # not shipped
    ({"robot": "no-such-arm"}, r"robot\.kind"),
    ({"robot": ["panda"]}, r"robot\.kind"),
    ({"tracking.epsilon2": 10.0}, r"tracking\.epsilon2"),  # inconsistent with epsilon1
    ({"world.surgeon_force": 0.0}, r"world\.surgeon_force"),
    ({"world.detector_dropout": 1.0}, r"world\.detector_dropout"),
    ({"world.detector_noise_px": float("nan")}, r"world\.detector_noise_px"),
    ({"world.surgeon_grip": True}, r"world\.surgeon_grip"),
    ({"world.nosuch": 1.0}, "nosuch"),
])
def test_apply_refusals_name_the_key(params: dict, named: str) -> None:
    with pytest.raises(SpaceError, match=named):
        apply(BASE, params)


@pytest.mark.parametrize(("key", "dist"), [
    ("world.surgeon_force", {"uniform": [0.5, 1e300]}),
    ("world.trocar_stiffness", {"loguniform": [1e-300, 2.0]}),
    ("world.detector_latency_s", {"normal": [0.04, 0.01], "min": 0.0, "max": 1e6}),
])
def test_a_world_draw_beyond_its_physical_range_is_refused_naming_the_key_and_the_range(key: str, dist: dict) -> None:
    """A sweep's random world value is checked at its corners against the field's range, before anything runs."""
    from lapwrench.sim.variation import RANGES

    lo, hi, _ = RANGES[key.removeprefix("world.")]
    with pytest.raises(SpaceError, match=r"^[^\n]+$") as info:
        check_dist(BASE, key, parse_dist(key, dist))
    assert f"{key} must be a number from {lo:g} to {hi:g}" in str(info.value)


# --------------------------------------------------------------------------- check_key


def test_check_key_accepts_good_values() -> None:
    check_key(BASE, "viscous.k_t", (0.1, 150.0, 10000.0))
    check_key(BASE, "world.trocar_stiffness", (0.5, 2.0))
    check_key(BASE, "robot", ("panda", "fr3", "ur5", "xarm7"))


def test_check_key_names_the_key_and_the_bad_value() -> None:
    with pytest.raises(SpaceError) as info:
        check_key(BASE, "viscous.k_t", (100.0, 20000.0))
    assert "viscous.k_t" in str(info.value) and "20000" in str(info.value)


@pytest.mark.parametrize("key", ["", 3, None, ("viscous", "k_t")])
def test_check_key_refuses_keys_that_are_not_dotted_names(key: object) -> None:
    with pytest.raises(SpaceError, match="dotted names"):
        check_key(BASE, key, (1.0,))  # type: ignore[arg-type]


def test_check_key_of_corners_bounds_every_clipped_normal_draw() -> None:
    d = parse_dist("world.surgeon_force", {"normal": [1.0, 5.0], "min": 0.1, "max": 3.0})
    check_key(BASE, "world.surgeon_force", d.corners())
    rng = np.random.default_rng(1)
    draws = {d.draw(rng) for _ in range(200)}  # apply is deterministic: each distinct value once
    assert min(draws) == 0.1 and max(draws) == 3.0  # clipped at both ends (each end takes ~40 % of a N(1, 5))
    for value in draws:
        apply(BASE, {"world.surgeon_force": value})


def test_integer_dist_on_an_integer_config_key_passes_check_key() -> None:
    d = parse_dist("inputs.max_instruments", {"integer": [1, 8]})
    check_key(BASE, "inputs.max_instruments", d.corners())


def test_integer_draws_apply_to_an_integer_config_key() -> None:
    d = parse_dist("inputs.max_instruments", {"integer": [1, 8]})
    rng = np.random.default_rng(0)
    draws = {d.draw(rng) for _ in range(100)}  # apply is deterministic: each distinct value once
    values = {apply(BASE, {"inputs.max_instruments": v})[0].inputs.max_instruments for v in draws}
    assert values == set(range(1, 9))


def test_world_value_given_as_int_is_stored_as_float() -> None:
    _, world = apply(BASE, {"world.incision_shift_mm": 0})
    assert world.incision_shift_mm == 0.0 and isinstance(world.incision_shift_mm, float)
    assert world.to_dict() == {**WorldVariation().to_dict(), "incision_shift_mm": 0.0}


@pytest.mark.parametrize("spec", [{"uniform": [-1e308, 1e308]}, {"integer": [0, 1e30]}])
def test_an_accepted_dist_can_always_draw(spec: dict) -> None:
    try:
        d = parse_dist("k", spec)
    except SpaceError:
        return
    d.draw(np.random.default_rng(0))


def test_check_dist_refuses_an_unclipped_normal_side_that_reaches_out_of_range() -> None:
    base = config_mod.load(None)
    with pytest.raises(SpaceError, match="without min can draw"):
        check_dist(base, "rcm.Kp", parse_dist("rcm.Kp", {"normal": [300, 1000]}))
    with pytest.raises(SpaceError, match="without max can draw"):
        check_dist(base, "rcm.Kp", parse_dist("rcm.Kp", {"normal": [300, 1000], "min": 50}))
    check_dist(base, "rcm.Kp", parse_dist("rcm.Kp", {"normal": [300, 1000], "min": 50, "max": 9000}))


def test_check_dist_accepts_an_unclipped_normal_that_stays_in_range() -> None:
    base = config_mod.load(None)
    check_dist(base, "rcm.Kp", parse_dist("rcm.Kp", {"normal": [5000, 100]}))  # 10 sd: 4000-6000
