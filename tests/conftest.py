"""Shared fixtures: the default configuration and robot models, built once per session."""

from __future__ import annotations

import os
from collections.abc import Iterator

import pytest
from helpers import thread_policy

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


# Tests that own the machine while they run: the real-time process and franky-sim (one server per machine,
# F/T freshness under a busy process), the browser UI at real time, and Ray clusters. `./run.sh test`
# runs every other test on two pytest-xdist workers first, then these alone, one at a time.
SERIAL_DIRS = ("hardware", "ui", "study", "examples")


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    root = config.rootpath / "tests"
    for item in items:
        parts = item.path.relative_to(root).parts if item.path.is_relative_to(root) else ()
        if parts and parts[0] in SERIAL_DIRS:
            item.add_marker(pytest.mark.serial)


@pytest.fixture(autouse=True)
def keeps_the_scheduling_policy() -> Iterator[None]:
    """A test must leave this process's main thread at the policy it found: a thread left at SCHED_FIFO
    (libfranka raises its caller to 99) passes it to every process started later, e.g. the browser of
    the UI tests, which then starves the machine. Put back, and the test fails."""
    before = thread_policy()
    yield
    after = thread_policy()
    if after != before:
        os.sched_setscheduler(0, before[0], os.sched_param(before[1]))
        pytest.fail(f"the test left the main thread's scheduling at {after} (policy, priority), found {before}")
