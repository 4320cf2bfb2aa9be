"""The documented ranges of every config number, and the interval and value checks behind them."""

from __future__ import annotations

import dataclasses
import math
import re
import typing

import pytest

from lapwrench import config, config_ranges
from lapwrench.config import Config, ConfigError, from_dict


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"rcm": {"Kp": 10**400}}, r"'rcm\.Kp' is too large, got <integer of about 400 digits>"),
        ({"interaction": {"k_min": 10**400}}, r"'interaction\.k_min' must lie in \[0, 63\]"),
        ({"camera": {"width": -(10**30)}}, r"'camera\.width' must lie in \[16, 8192\]"),
        ({"rcm": {"Kp": float("inf")}}, r"'rcm\.Kp' must be finite"),
        ({"rcm": {"Kd": float("-inf")}}, r"'rcm\.Kd' must be finite"),
    ],
)
def test_huge_and_infinite_numbers_are_refused(data: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        from_dict(data)


@pytest.mark.parametrize(
    ("data", "key"),
    [
        # the campaign's nonsense (issue 11, item 11)
        ({"camera": {"u0": 700.0}}, "camera.u0"),
        ({"camera": {"v0": 480.0}}, "camera.v0"),
        ({"camera": {"u0": 0.0}}, "camera.u0"),
        ({"camera": {"fx": 1e-9}}, "camera.fx"),
        ({"camera": {"fy": 1e9}}, "camera.fy"),
        ({"camera": {"width": 100_000}}, "camera.width"),
        ({"interaction": {"k_min": 64}}, "interaction.k_min"),
        ({"interaction": {"contact_threshold": 255}}, "interaction.contact_threshold"),
        ({"interaction": {"k_H": 1e-3}}, "interaction.k_H"),
        ({"robot": {"limit_fraction": 1e-300}}, "robot.limit_fraction"),
        ({"robot": {"limit_fraction": 1.01}}, "robot.limit_fraction"),
        ({"robot": {"position_margin": 1.0}}, "robot.position_margin"),
        ({"robot": {"control_rate_hz": 0}}, "robot.control_rate_hz"),
        ({"robot": {"control_rate_hz": float("nan")}}, "robot.control_rate_hz"),
        ({"rcm": {"Kp": 1e300}}, "rcm.Kp"),
        ({"rcm": {"Kd": 1e100}}, "rcm.Kd"),  # raised LinAlgError in the tick
        ({"viscous": {"k_t": 1e300}}, "viscous.k_t"),
        ({"viscous": {"k_f": 1e-6}}, "viscous.k_f"),
        ({"tracking": {"F_max": 1e300}}, "tracking.F_max"),
        ({"tracking": {"epsilon1": 900.0, "epsilon2": 1000.0}}, "tracking.epsilon1"),  # beyond the 800 px diagonal
        ({"adaptive_rcm": {"alpha": 1e300}}, "adaptive_rcm.alpha"),
        ({"adaptive_rcm": {"beta": 1e300}}, "adaptive_rcm.beta"),
        ({"motion": {"joint_limit_stiffness": 1e300}}, "motion.joint_limit_stiffness"),
        ({"motion": {"stop_time": 1e-9}}, "motion.stop_time"),
        ({"scope": {"length": 1e6}}, "scope.length"),  # crashed MuJoCo
        ({"scope": {"oblique_angle_deg": 90.0}}, "scope.oblique_angle_deg"),
        ({"scope": {"handle_offset": 0.3}}, "scope.handle_offset"),
        ({"envelope": {"roll_range": 4.0}}, "envelope.roll_range"),
        ({"envelope": {"roll_range": 3.1416}}, "envelope.roll_range"),  # its wall would sit on the wrap at pi
        ({"envelope": {"depth_max": 0.3}}, "envelope.depth_max"),
        ({"envelope": {"pivot_speed_max": 1e9}}, "envelope.pivot_speed_max"),
        ({"safety": {"max_residual_force": 1e9}}, "safety.max_residual_force"),
        ({"inputs": {"max_instruments": 0}}, "inputs.max_instruments"),
        ({"inputs": {"max_image_age": 1e9}}, "inputs.max_image_age"),
    ],
)
def test_values_without_physical_sense_are_refused(data: dict, key: str) -> None:
    with pytest.raises(ConfigError, match=re.escape(f"'{key}'")) as err:
        from_dict(data)
    assert err.value.key == key


def test_every_number_has_a_documented_range_holding_its_default() -> None:
    numeric = 0
    for section, cls in typing.get_type_hints(Config).items():
        if not dataclasses.is_dataclass(cls):
            continue  # the cues: section (its parameters are the plugins' own)
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            if hints[f.name] not in (int, float):
                continue
            numeric += 1
            bounds = f.metadata.get("range")
            assert isinstance(bounds, config.Range), f"{section}.{f.name} has no range"
            assert bounds.why, f"{section}.{f.name}: say why (units at least)"
            assert f.default in bounds, f"{section}.{f.name}"
    assert numeric >= 50


# -- the machinery itself, on made-up fields ---------------------------------------------------------------
def test_interval_notation_with_open_and_closed_ends() -> None:
    r = config_ranges.interval("(0, pi]", "rad")
    assert (r.lo, r.hi, r.lo_open, r.hi_open, r.why) == (0.0, math.pi, True, False, "rad")
    assert 0.0 not in r and 1e-12 in r and math.pi in r and 3.15 not in r
    assert str(r) == "(0, 3.14159]"
    closed = config_ranges.interval(" [ -1 , 2 ) ", "")
    assert -1.0 in closed and 2.0 not in closed
    with pytest.raises(ValueError, match="bad interval"):
        config_ranges.interval("0..1", "")


def test_check_value_types_and_bounds() -> None:
    unit = config_ranges.interval("[0, 1]", "a fraction")
    assert config_ranges.check_value("a.x", 1, float, unit) == 1.0
    assert config_ranges.check_value("a.n", 3, int, None) == 3
    with pytest.raises(ConfigError, match=r"'a\.x' must lie in \[0, 1\] \(a fraction\), got 1\.5") as err:
        config_ranges.check_value("a.x", 1.5, float, unit)
    assert err.value.key == "a.x"
    with pytest.raises(ConfigError, match="must be an integer"):
        config_ranges.check_value("a.n", 2.0, int, None)
    with pytest.raises(ConfigError, match="must be a number"):
        config_ranges.check_value("a.x", True, float, None)
    with pytest.raises(ConfigError, match="must be true or false"):
        config_ranges.check_value("a.b", 1, bool, None)
    mode = typing.Literal["fast", "slow"]
    assert config_ranges.check_value("a.m", "slow", mode, None) == "slow"
    with pytest.raises(ConfigError, match=r"must be one of \['fast', 'slow'\]"):
        config_ranges.check_value("a.m", "medium", mode, None)


def test_lists_of_numbers_are_checked_element_by_element() -> None:
    unit = config_ranges.interval("[0, 1]", "")
    three = tuple[float, float, float]
    assert config_ranges.check_value("a.v", [0, 0.5, 1], three, unit) == (0.0, 0.5, 1.0)
    assert config_ranges.check_value("a.w", [0.25], tuple[float, ...], unit) == (0.25,)
    with pytest.raises(ConfigError, match="must be a list of 3 numbers"):
        config_ranges.check_value("a.v", [0, 1], three, unit)
    with pytest.raises(ConfigError, match="one or more numbers"):
        config_ranges.check_value("a.w", [], tuple[float, ...], unit)
    with pytest.raises(ConfigError, match=r"'a\.v\[2\]' must lie in"):
        config_ranges.check_value("a.v", [0, 0.5, 2], three, unit)


# -- checks between keys (a config audit: each of these passed validation and then held, stopped or diverged) --
@pytest.mark.parametrize(
    ("data", "key"),
    [
        # tip 14.5 mm beyond p_R at the start, below depth_min 30 mm: the supervisor held on the first tick
        ({"scope": {"lambda0": 0.95}}, "scope.lambda0"),
        ({"scope": {"lambda0": 0.3}}, "scope.lambda0"),  # 203 mm, beyond depth_max 120 mm: the same hold
        ({"envelope": {"depth_min": 0.06}}, "scope.lambda0"),  # the default start, 58 mm, now too shallow
        # at depth_max the RCM point would lie 0.17 m from {E}, the handle 0.2 m: inside the incision
        ({"scope": {"handle_offset": 0.2, "lambda0": 0.6}, "envelope": {"depth_max": 0.12}}, "envelope.depth_max"),
    ],
)
def test_depths_the_scope_cannot_start_at_or_reach_safely_are_refused(data: dict, key: str) -> None:
    with pytest.raises(ConfigError, match=re.escape(f"'{key}'")) as err:
        from_dict(data)
    assert err.value.key == key


@pytest.mark.parametrize(
    ("data", "key"),
    [
        # 2 Hz: a 30 N push took the paper's gains to 77 mm of RCM error; 20 Hz: K_p 10000 took 4 mm to 14 mm
        ({"robot": {"control_rate_hz": 2}}, "robot.control_rate_hz"),
        ({"robot": {"control_rate_hz": 20}, "rcm": {"Kp": 10000, "Kd": 200}}, "robot.control_rate_hz"),
        # the explicit step takes K_d at the old velocity: 2000 N s/m ran the joints to their limits and stopped
        ({"motion": {"integrator": "explicit"}, "rcm": {"Kp": 2000, "Kd": 2000}}, "robot.control_rate_hz"),
        # overdamped: 2.6 of 4 mm left after 3 s; K_p 1e-6 left all of it
        ({"rcm": {"Kp": 300, "Kd": 2000}}, "rcm.Kp"),
        ({"rcm": {"Kp": 1e-6}}, "rcm.Kp"),
        # underdamped: K_d 1e-6 left 3.9 of 4 mm after 3 s (Panda); K_d 2 on the UR5 1.5 of 4 mm after 2 s
        ({"rcm": {"Kd": 1e-6}}, "rcm.Kd"),
        ({"rcm": {"Kd": 5.0}}, "rcm.Kd"),
        # the null-space brake at 100 Hz with 5 ms: dt / stop_time = 2, it rings forever
        ({"robot": {"control_rate_hz": 100}, "motion": {"stop_time": 0.005}}, "motion.stop_time"),
    ],
)
def test_rcm_gains_and_brake_the_control_rate_cannot_integrate_are_refused(data: dict, key: str) -> None:
    with pytest.raises(ConfigError, match=re.escape(f"'{key}'")) as err:
        from_dict(data)
    assert err.value.key == key


def test_the_checks_between_keys_leave_the_paper_the_studies_and_the_tests_room() -> None:
    """Corners of studies/tune.yaml's box, the rates the suite uses, and the limits of each new check."""
    for kp in (1000.0, 8000.0):
        for kd in (10.0, 100.0):
            from_dict({"rcm": {"Kp": kp, "Kd": kd}})
    for rate in (250, 500, 2000):
        from_dict({"robot": {"control_rate_hz": rate}, "rcm": {"Kp": 10000, "Kd": 10}})
    from_dict({"robot": {"control_rate_hz": 50}, "rcm": {"Kp": 10000, "Kd": 200}})  # converged in a virtual run
    from_dict({"rcm": {"Kp": 20.0, "Kd": 20.0}})  # slowest pole exactly 1/s
    from_dict({"robot": {"control_rate_hz": 1000}, "motion": {"stop_time": 0.005}})  # 5 ticks
    from_dict({"scope": {"lambda0": 0.9}, "envelope": {"depth_min": 0.028}})  # starts at 29 mm
    from_dict({"motion": {"integrator": "explicit"}})


@pytest.mark.parametrize(
    ("data", "match"),
    [
        ({"rcm": {"kp": 300.0}}, r"unknown config key 'rcm\.kp' \(did you mean 'Kp'\?\); known keys here"),
        ({"RCM": {}}, r"unknown config key 'RCM' \(did you mean 'rcm'\?\)"),
        ({"trackng": {}}, r"unknown config key 'trackng' \(did you mean 'tracking'\?\)"),
        ({"viscous": {"kt": 1.0}}, r"unknown config key 'viscous\.kt' \(did you mean 'k_t'\?\)"),
        ({"cues": {"keep_out": {"radus": 0.03}}}, r"'cues\.keep_out\.radus' \(did you mean 'radius'\?\)"),
    ],
)
def test_a_mistyped_key_is_refused_with_the_key_it_resembles(data: dict, match: str) -> None:
    with pytest.raises(ConfigError, match=match):
        from_dict(data)


def test_a_key_like_no_other_gets_no_suggestion() -> None:
    with pytest.raises(ConfigError) as err:
        from_dict({"rcm": {"x" * 1_000_000: 1}})
    assert "did you mean" not in str(err.value) and len(str(err.value)) < 300
    with pytest.raises(ConfigError) as err:
        from_dict({"nope": {}})  # 'scope' is not what it meant
    assert "did you mean" not in str(err.value)
