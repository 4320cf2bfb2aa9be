"""The detectors of the simulated runs: the shipped model on a chosen number of threads, and the
projection of the simulator's geometry."""

from __future__ import annotations

import numpy as np

from lapwrench.config import load
from lapwrench.sim.detectors import ProjectedInstruments, make_detector
from lapwrench.sim.scripts import park_instrument, tissue_point
from lapwrench.sim.world import SimWorld

CFG = load()


def _frame_with_an_instrument(world: SimWorld) -> np.ndarray:
    world.set_instrument_tip(0, tissue_point(world, 0.01, 0.005))
    park_instrument(world, 1)
    world.step(world.scene.q0)
    return world.render()


def test_the_shipped_detector_on_one_thread_finds_what_it_finds_on_its_default(world: SimWorld) -> None:
    frame = _frame_with_an_instrument(world)
    one, name = make_detector("shipped", world, CFG, threads=1)
    default, _ = make_detector("shipped", world, CFG)
    assert one.session.get_session_options().intra_op_num_threads == 1  # type: ignore[attr-defined]
    assert "YOLO ONNX" in name
    found = one.detect(frame)
    assert found and found == default.detect(frame)


def test_the_projected_detector_sees_the_tips_in_view_only(world: SimWorld) -> None:
    det, name = make_detector("projected", world, CFG, threads=1)  # no threads to set: ignored
    assert isinstance(det, ProjectedInstruments) and "no detector" in name
    _frame_with_an_instrument(world)
    found = det.detect(np.zeros((0, 0, 3), np.uint8))
    assert len(found) == 1  # the parked instrument is out of view
    u, v = found[0].point
    assert 0 <= u < CFG.camera.width and 0 <= v < CFG.camera.height
