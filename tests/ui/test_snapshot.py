"""The page's snapshot of the simulated session."""

from __future__ import annotations

import numpy as np

from lapwrench.config import Config
from lapwrench.ui.playback import ScriptPlayer, make_script
from lapwrench.ui.session import build_loop
from lapwrench.ui.snapshot import take_snapshot


def test_a_snapshot_draws_each_cue_at_its_point_and_keeps_the_last_five_alarms(cfg: Config) -> None:
    closed = build_loop(cfg, 0, "projected")
    try:
        closed.world.set_hand_wrench(force=[0.0, 3.0, 0.0], torque=[0.0, 0.0, 0.0])
        res = None
        for _ in range(50):
            res = closed.step(30.0)
        alarms = [f"alarm {i}" for i in range(7)]
        snap = take_snapshot(closed, res, held=None, alarms=alarms, rcm_error=2e-4, disturbance=True, script=None,
                             pending_config=True)
        assert res is not None and snap.t == closed.t and snap.mode == res.mode
        assert snap.alarms == tuple(alarms[-5:]) and snap.rcm_error_mm == 0.2
        assert snap.disturbance and snap.pending_config and not snap.script and snap.script_name == ""
        assert set(snap.cue_forces) == set(res.wrenches)
        point, force = snap.cue_forces["rcm"]
        assert np.array_equal(point, res.p_R) and np.array_equal(force, res.wrenches["rcm"][3:])
        assert np.array_equal(snap.cue_forces["viscous"][0], res.p_G)
        assert snap.body_pos.shape == (closed.world.model.nbody, 3)

        player = ScriptPlayer(make_script("view-adjustment", 30.0), closed.t - 0.5)
        held = take_snapshot(closed, None, held="rcm_error: 3 mm", alarms=[], rcm_error=0.003, disturbance=False,
                             script=player, pending_config=False)
        assert held.mode == "held" and held.delta == 0.0 and held.cue_forces == {}
        assert held.script and held.script_name == player.name and abs(held.script_time - 0.5) < 1e-9
        assert np.allclose(held.p_R, closed.world.shaft_axis()[0])  # no tick to draw: the shaft's entry
    finally:
        closed.world.close()
