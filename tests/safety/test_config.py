"""The supervisor's thresholds, states and events (:mod:`lapwrench.safety.config`): where the bounds come
from, and the thresholds :class:`SupervisorConfig` refuses (a bad threshold would switch a watch off)."""

from __future__ import annotations

import dataclasses
import math

import pytest

from lapwrench.config import load
from lapwrench.robot.model import RobotModel
from lapwrench.safety.config import SupervisorConfig, SupervisorEvent, SupervisorState
from lapwrench.safety.supervisor import SafetySupervisor
from lapwrench.virtual import DEFAULT_Q0

POSITIVE = (
    "check_fraction", "stop_fraction", "max_rcm_error", "max_residual_force", "max_joint_step", "cycle_budget",
    "rest_velocity",
)


def test_the_defaults_are_the_shipped_yaml_sections() -> None:
    cfg = load()
    c = SupervisorConfig()
    assert c.max_rcm_error == cfg.safety.max_rcm_error
    assert c.max_residual_force == cfg.safety.max_residual_force
    assert c.residual_force_time == cfg.safety.residual_force_time
    # the depth bounds are the envelope's range widened by the safety tolerance on each side
    assert c.depth_min == pytest.approx(cfg.envelope.depth_min - cfg.safety.depth_tolerance)
    assert c.depth_max == pytest.approx(cfg.envelope.depth_max + cfg.safety.depth_tolerance)


def test_from_config_reads_the_bounds_and_overrides_win() -> None:
    cfg = load().replace(
        safety={"max_rcm_error": 0.002, "depth_tolerance": 0.0, "max_residual_force": 12.0, "residual_force_time": 0.1},
        envelope={"depth_min": 0.05, "depth_max": 0.09},
    )
    c = SupervisorConfig.from_config(cfg, max_consecutive_misses=0, depth_max=0.2)
    assert (c.max_rcm_error, c.max_residual_force, c.residual_force_time) == (0.002, 12.0, 0.1)
    assert (c.depth_min, c.depth_max) == (0.05, 0.2)  # tolerance 0; the override replaces a bound
    assert c.max_consecutive_misses == 0
    assert c.cycle_budget == SupervisorConfig().cycle_budget  # not overridden: the default


def test_from_config_refuses_an_unknown_threshold_by_name() -> None:
    with pytest.raises(TypeError, match="max_rcm_eror"):
        SupervisorConfig.from_config(load(), max_rcm_eror=0.01)


def test_from_config_checks_the_combined_bounds() -> None:
    """Each YAML section is valid alone; an override that crosses the depth range is refused."""
    with pytest.raises(ValueError, match="depth_min < depth_max"):
        SupervisorConfig.from_config(load(), depth_min=0.2)


def test_a_config_is_frozen() -> None:
    c = SupervisorConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        c.max_rcm_error = 1.0  # type: ignore[misc]
    assert dataclasses.replace(c, max_rcm_error=0.01).max_rcm_error == 0.01


@pytest.mark.parametrize("name", POSITIVE)
@pytest.mark.parametrize("bad", [0.0, -0.1, math.nan, math.inf, -math.inf])
def test_a_threshold_that_must_be_positive_is_refused_by_name(name: str, bad: float) -> None:
    with pytest.raises(ValueError, match=rf"supervisor\.{name} must be positive, got {bad!r}"):
        SupervisorConfig(**{name: bad})


@pytest.mark.parametrize("name", ["check_fraction", "stop_fraction"])
def test_a_fraction_of_the_limits_above_one_is_refused(name: str) -> None:
    with pytest.raises(ValueError, match="<= 1"):
        SupervisorConfig(**{name: 1.01})
    assert getattr(SupervisorConfig(**{name: 1.0}), name) == 1.0  # the hard limits themselves


@pytest.mark.parametrize(
    ("depth_min", "depth_max"),
    [(0.1, 0.05), (0.05, 0.05), (math.nan, 0.1), (0.02, math.nan), (-math.inf, 0.1), (0.02, math.inf)],
)
def test_the_depth_range_must_be_finite_and_ordered(depth_min: float, depth_max: float) -> None:
    with pytest.raises(ValueError, match="finite depth_min < depth_max"):
        SupervisorConfig(depth_min=depth_min, depth_max=depth_max)


@pytest.mark.parametrize(
    ("stop", "warn"), [(-0.01, 0.04), (0.05, 0.04), (math.nan, 0.04), (0.01, math.nan)]
)
def test_the_joint_margins_must_be_ordered(stop: float, warn: float) -> None:
    with pytest.raises(ValueError, match="joint_stop_margin <= joint_warn_margin"):
        SupervisorConfig(joint_stop_margin=stop, joint_warn_margin=warn)


def test_a_negative_miss_count_is_refused() -> None:
    with pytest.raises(ValueError, match="max_consecutive_misses"):
        SupervisorConfig(max_consecutive_misses=-1)
    assert SupervisorConfig(max_consecutive_misses=0).max_consecutive_misses == 0  # 0: never stop



@pytest.mark.parametrize(
    ("name", "bad"),
    [
        ("position_tolerance", math.nan),  # NaN: the command position check never fires
        ("position_tolerance", math.inf),
        ("position_tolerance", -0.1),
        ("residual_force_time", math.nan),  # NaN: a finite residual force never holds
        ("residual_force_time", math.inf),
        ("residual_force_time", -0.1),
        ("max_consecutive_misses", math.nan),  # NaN: deadline misses never stop
        ("max_consecutive_misses", 2.5),
        ("max_events", -1),  # refused later by collections.deque, with no name
    ],
)
def test_a_threshold_that_would_switch_a_check_off_is_refused_by_name(name: str, bad: float) -> None:
    with pytest.raises(ValueError, match=rf"supervisor\.{name}"):
        SupervisorConfig(**{name: bad})


@pytest.mark.parametrize("name", ["check_fraction", "max_rcm_error", "cycle_budget"])
def test_a_threshold_of_the_wrong_type_is_refused_by_name(name: str) -> None:
    with pytest.raises((TypeError, ValueError), match=rf"supervisor\.{name}"):
        SupervisorConfig(**{name: "0.5"})


def test_no_tolerance_lets_a_slow_command_past_the_position_limit() -> None:
    """Why the unchecked ``position_tolerance`` matters: with NaN, a slow command past the upper limit
    passes the supervisor (the default tolerance refuses it). Either the config or the check must refuse."""
    limits = RobotModel("panda").limits
    q0 = DEFAULT_Q0.copy()
    q0[0] = limits.position_upper[0]  # at the limit, at rest
    past = q0.copy()
    past[0] += 2e-6  # 2 mrad/s from rest: inside the velocity, acceleration and jerk limits
    for tol in (SupervisorConfig().position_tolerance, math.nan):
        try:
            cfg = SupervisorConfig(position_tolerance=tol)
        except ValueError:
            continue  # refused by the config: fine
        s = SafetySupervisor(limits, 1e-3, cfg)
        s.start(q0)
        problem = s.check_command(past)
        assert problem is not None and problem[0] == "command_position", (tol, problem)


def test_the_states_read_as_their_names() -> None:
    """States are logged and shown as text: each is its lower-case name and parses back."""
    assert [str(s) for s in SupervisorState] == ["running", "stopping", "holding"]
    assert SupervisorState("holding") is SupervisorState.HOLDING
    with pytest.raises(ValueError):
        SupervisorState("halted")


def test_an_event_is_a_frozen_record() -> None:
    ev = SupervisorEvent(1.5, "stop", "stop requested")
    assert (ev.time, ev.kind, ev.message) == (1.5, "stop", "stop requested")
    assert ev == SupervisorEvent(1.5, "stop", "stop requested")
    with pytest.raises(dataclasses.FrozenInstanceError):
        ev.kind = "start"  # type: ignore[misc]
