"""lapwrench.robot.arms.spec: one arm as data, checked when it is written."""

from __future__ import annotations

import dataclasses

import pytest

from lapwrench.robot.arms import ARM_SPECS
from lapwrench.robot.arms.spec import PackageUrdf, RobotDescriptionError


def test_a_description_from_a_missing_package_names_the_package() -> None:
    with pytest.raises(RobotDescriptionError, match="pip install no-such-robot-pkg"):
        PackageUrdf("no-such-robot-pkg", "robot.urdf").path()


def test_a_package_without_the_file_says_so() -> None:
    with pytest.raises(RobotDescriptionError, match=r"ships no nowhere/robot\.urdf"):
        PackageUrdf("example-robot-data", "nowhere/robot.urdf").path()


@pytest.mark.parametrize("field", ["home_pose", "servo_damping"])
def test_a_per_joint_vector_of_the_wrong_length_is_refused(field: str) -> None:
    spec = ARM_SPECS["panda"]
    with pytest.raises(ValueError, match=f"{field} need one value per joint"):
        dataclasses.replace(spec, **{field: getattr(spec, field)[:-1]})


def test_a_limit_table_of_the_wrong_length_is_refused() -> None:
    spec = ARM_SPECS["ur5"]
    short = dataclasses.replace(spec.limits, jerk=spec.limits.jerk[:-1])
    with pytest.raises(ValueError, match=r"limits\.jerk"):
        dataclasses.replace(spec, limits=short)


def test_a_non_positive_command_period_is_refused() -> None:
    with pytest.raises(ValueError, match="command_period_s"):
        dataclasses.replace(ARM_SPECS["fr3"], command_period_s=0.0)


@pytest.mark.parametrize("value", [0.0, -1.0, float("nan"), float("inf")])
@pytest.mark.parametrize("table", ["velocity", "acceleration", "jerk", "torque"])
def test_a_limit_that_is_not_finite_and_positive_is_refused(table: str, value: float) -> None:
    spec = ARM_SPECS["panda"]
    bad = dataclasses.replace(spec.limits, **{table: (value, *getattr(spec.limits, table)[1:])})
    with pytest.raises(ValueError, match=f"limits.{table} must be finite positive numbers"):
        dataclasses.replace(spec, limits=bad)
