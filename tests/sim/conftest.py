"""Shared fixtures for the simulation tests (headless EGL rendering by default)."""

from __future__ import annotations

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from collections.abc import Iterator

import pytest

from lapwrench.sim.scene.build import Scene, build_scene
from lapwrench.sim.scene.config import SceneConfig
from lapwrench.sim.world import SimWorld


@pytest.fixture(scope="session")
def panda_scene() -> Scene:
    """The default Panda world, compiled once per session."""
    return build_scene(SceneConfig(kind="panda"))


@pytest.fixture
def world(panda_scene: Scene) -> Iterator[SimWorld]:
    """A fresh SimWorld on the shared Panda scene (its own MjData)."""
    w = SimWorld(panda_scene)
    yield w
    w.close()
