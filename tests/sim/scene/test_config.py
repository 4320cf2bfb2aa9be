"""Scene configurations the builder refuses."""

from __future__ import annotations

import pytest

from lapwrench.sim.scene.config import PhantomConfig, SceneConfig


def test_invalid_configs_are_rejected() -> None:
    with pytest.raises(ValueError, match="timestep"):
        SceneConfig(timestep=0.0007)
    with pytest.raises(ValueError, match="unknown robot"):
        SceneConfig(kind="kuka")
    with pytest.raises(ValueError, match="wall_stiffness"):
        PhantomConfig(wall_stiffness=-1.0)
    with pytest.raises(ValueError, match="rcm_lambda0"):
        SceneConfig(rcm_lambda0=1.2)
