"""What the page draws: a :class:`Snapshot` of the simulated session, taken in the sim thread every few
ticks (:mod:`lapwrench.ui.session`) by :func:`take_snapshot`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lapwrench.controller import TickResult
from lapwrench.robot.description import FRAME_C, FRAME_H
from lapwrench.sim.loop import ClosedLoop
from lapwrench.ui.playback import ScriptPlayer


@dataclass(frozen=True)
class Snapshot:
    """What the page draws, taken in the sim thread (vectors in {B}, SI units)."""

    t: float
    mode: str
    delta: float
    held: str | None
    alarms: tuple[str, ...]
    body_pos: np.ndarray
    body_quat: np.ndarray
    hand_point: np.ndarray
    hand_force: np.ndarray
    cue_forces: dict[str, tuple[np.ndarray, np.ndarray]]  # name -> (point, force)
    trocar_force: np.ndarray
    incision: np.ndarray
    p_R: np.ndarray
    shaft_dir: np.ndarray
    rcm_error_mm: float
    disturbance: bool
    script: bool
    pending_config: bool
    detections: tuple[tuple[tuple[float, float, float, float], tuple[float, float]], ...] = ()
    script_name: str = ""  # the scenario playing (:data:`~lapwrench.ui.playback.PLAYABLE`), "" if none
    script_time: float = 0.0  # s since it started


def take_snapshot(
    closed: ClosedLoop,
    last: TickResult | None,
    *,
    held: str | None,
    alarms: list[str],
    rcm_error: float,
    disturbance: bool,
    script: ScriptPlayer | None,
    pending_config: bool,
) -> Snapshot:
    """The session's state for the page: the world's bodies and forces, the last tick's cue forces (each
    drawn at its point: the handle {H}, the camera {C}, the RCM point; the others at the closest point
    {G}), the latest detections, the last five alarms. ``held``: the hold's reason (None when running);
    ``rcm_error``: the physical RCM error (m)."""
    w = closed.world
    p_E, d = w.shaft_axis()
    p_H, _ = w.frame_pose(FRAME_H)
    points = {"interaction": p_H, "tracking": w.frame_pose(FRAME_C)[0]}
    cues: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    if last is not None:
        points["rcm"] = last.p_R
        cues = {n: (points.get(n, last.p_G), np.asarray(v[3:], float).copy()) for n, v in last.wrenches.items()}
    dets: tuple = ()
    if closed.detection is not None:
        latest = closed.detection.latest(closed.t)
        if latest is not None:
            dets = tuple((tuple(map(float, x.box)), tuple(map(float, x.point))) for x in latest.detections)
    return Snapshot(
        t=closed.t, mode="held" if held else closed.last_mode, delta=0.0 if last is None else last.delta,
        held=held, alarms=tuple(alarms[-5:]), body_pos=w.data.xpos.copy(),
        body_quat=w.data.xquat.copy(), hand_point=p_H, hand_force=w.hand_force(), cue_forces=cues,
        trocar_force=w.contact_force(), incision=w.incision_position(),
        p_R=p_E if last is None else last.p_R.copy(), shaft_dir=d, rcm_error_mm=rcm_error * 1e3,
        disturbance=disturbance, script=script is not None, pending_config=pending_config, detections=dets,
        script_name="" if script is None else script.name,
        script_time=0.0 if script is None else script.elapsed(closed.t),
    )
