"""Fixtures for the hardware-path tests (helpers live in ``support.py``)."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from collections.abc import Iterator
from typing import Any

import pytest
from hardware.support import FRANKYSIM_MISSING

from lapwrench.config import Config, load
from lapwrench.hardware.frankysim import FrankySimServer
from lapwrench.hardware.rt import bus_layout
from lapwrench.hardware.shm import Bus
from lapwrench.virtual import DEFAULT_Q0


@pytest.fixture(scope="session")
def fr3_cfg() -> Config:
    return load().replace(robot={"kind": "fr3"})


@pytest.fixture(scope="session")
def panda_cfg() -> Config:
    return load()


@pytest.fixture(scope="module")
def frankysim() -> Iterator[FrankySimServer]:
    """franky-sim on 127.0.0.1 in a child process for the module; always stopped by its pid."""
    if FRANKYSIM_MISSING:
        pytest.skip(f"pylibfranka/franky-sim cannot be imported: {FRANKYSIM_MISSING}")
    server = FrankySimServer(DEFAULT_Q0)
    try:
        server.start()
        yield server
    finally:
        server.stop()


@pytest.fixture
def sim_world() -> Iterator[Any]:
    from lapwrench.sim.world import SimWorld

    w = SimWorld()
    yield w
    w.close()


@pytest.fixture
def bus() -> Iterator[Bus]:
    """A small shared-memory bus (8 log rows, 16 event rows), unlinked after the test."""
    b = Bus.create(bus_layout(log_rows=8, event_rows=16))
    try:
        yield b
    finally:
        b.close()
