"""Robot factories for :attr:`~lapwrench.hardware.rt.spec.RtSpec.robot_factory` (module level:
picklable for the spawned child)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np


def franka_factory(
    cfg: Any,
    script: Any,
    *,
    robot_ip: str,
    kind: str,
    realtime: str = "enforce",
    ext_wrench_sign: str = "robot_on_environment",
    report_external_force: bool = True,
    payload: bool = True,
) -> Any:
    """A :class:`~lapwrench.hardware.franka.FrankaRobot` (use with ``functools.partial``)."""
    from lapwrench.hardware.franka import FrankaRobot, Payload
    from lapwrench.robot.description import ScopeGeometry

    return FrankaRobot(
        robot_ip,
        kind=kind,
        realtime=realtime,  # type: ignore[arg-type]
        ext_wrench_sign=ext_wrench_sign,  # type: ignore[arg-type]
        report_external_force=report_external_force,
        load=Payload.from_scope(ScopeGeometry.from_config(cfg.scope)) if payload else None,
        dt=cfg.robot.dt,
    )


def _script_force(script: Any, _t: float) -> np.ndarray:
    return script.force_H()


def sim_factory(cfg: Any, script: Any, *, realtime: bool = True, q0: Any = None) -> Any:
    """A :class:`~lapwrench.sim.robot.SimRobot` on the configured scene; a dry-run ``script``'s hand
    force is applied to the handle (on the script's clock, shared with the parent)."""
    from lapwrench.sim.robot import SimRobot
    from lapwrench.sim.scene.config import SceneConfig
    from lapwrench.sim.world import SimWorld

    world = SimWorld(SceneConfig.from_config(cfg))
    hand = None if script is None else _bind(_script_force, script)
    return SimRobot(world, q0=q0, realtime=realtime, hand_force_H=hand)


def _bind(f: Callable[..., Any], *args: Any) -> Callable[..., Any]:
    import functools

    return functools.partial(f, *args)
