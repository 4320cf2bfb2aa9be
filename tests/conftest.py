"""Shared fixtures: the default configuration and robot models, built once per session."""

from __future__ import annotations

import pytest

from lapwrench.config import Config, load
from lapwrench.robot.model import RobotModel


@pytest.fixture(scope="session")
def cfg() -> Config:
    return load()


@pytest.fixture(scope="session", params=["panda", "fr3"])
def any_model(request: pytest.FixtureRequest) -> RobotModel:
    return RobotModel(request.param)


@pytest.fixture(scope="session")
def panda() -> RobotModel:
    return RobotModel("panda")

