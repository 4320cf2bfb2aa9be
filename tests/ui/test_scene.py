"""The 3D scene: every drawn geom of the MuJoCo model, the bodies moved from snapshots, force arrows."""

from __future__ import annotations

from collections.abc import Iterator

import mujoco
import numpy as np
import pytest

from lapwrench.config import Config
from lapwrench.sim.scene.build import build_scene
from lapwrench.sim.scene.config import SceneConfig
from lapwrench.ui.scene import ARROW_SCALE, SceneDrawer, cue_color, force_segments, geom_color, geom_mesh
from lapwrench.ui.snapshot import Snapshot

viser = pytest.importorskip("viser")


@pytest.fixture(scope="module")
def model(cfg: Config) -> mujoco.MjModel:
    return build_scene(SceneConfig.from_config(cfg)).model


def snapshot(model: mujoco.MjModel, data: mujoco.MjData) -> Snapshot:
    z = np.zeros(3)
    return Snapshot(
        t=0.0, mode="idle", delta=0.0, held=None, alarms=(), body_pos=data.xpos.copy(), body_quat=data.xquat.copy(),
        hand_point=np.array([0.5, 0.0, 0.6]), hand_force=np.array([10.0, 0.0, 0.0]),
        cue_forces={"rcm": (np.array([0.5, 0.0, 0.25]), np.array([0.0, 2.0, 0.0])), "zoom": (z, z)},
        trocar_force=np.array([0.0, 0.0, 1.0]), incision=np.array([0.5, 0.0, 0.25]), p_R=np.array([0.5, 0.0, 0.25]),
        shaft_dir=np.array([0.0, 0.0, -1.0]), rcm_error_mm=0.0, disturbance=False, script=False, pending_config=False,
    )


def test_every_solid_geom_has_a_mesh_in_its_own_frame(model: mujoco.MjModel) -> None:
    drawn = 0
    for g in range(model.ngeom):
        mesh = geom_mesh(model, g)
        if int(model.geom_type[g]) == mujoco.mjtGeom.mjGEOM_PLANE:
            assert mesh is None
            continue
        assert mesh is not None
        v, f = mesh
        assert v.shape[1] == 3 and f.shape[1] == 3 and f.max() < len(v)
        # the mesh fits the geom's bounding radius
        assert np.linalg.norm(v, axis=1).max() <= model.geom_rbound[g] * 1.01 + 1e-6
        color, alpha = geom_color(model, g)
        assert all(0 <= c <= 255 for c in color) and 0.0 <= alpha <= 1.0
        drawn += 1
    assert drawn == model.ngeom - 1  # all but the floor


def test_force_segments_start_where_each_force_acts(model: mujoco.MjModel) -> None:
    data = mujoco.MjData(model)
    snap = snapshot(model, data)
    names, seg = force_segments(snap)
    assert names == ["hand", "rcm", "zoom", "trocar"]
    np.testing.assert_allclose(seg[0, 0], snap.hand_point)
    np.testing.assert_allclose(seg[0, 1] - seg[0, 0], ARROW_SCALE * snap.hand_force)
    np.testing.assert_allclose(seg[3, 0], snap.incision)


def test_cue_colors_are_fixed_for_the_paper_cues_and_distinct_for_plugins() -> None:
    assert cue_color("rcm", 0) == cue_color("rcm", 7)
    assert len({cue_color(f"plugin{i}", i) for i in range(4)}) == 4


@pytest.fixture
def drawn(model: mujoco.MjModel) -> Iterator[tuple[SceneDrawer, mujoco.MjData, dict[str, tuple[int, int, int]]]]:
    """A drawer on a live server, the data it draws from (kinematics done) and the cue colours."""
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        data = mujoco.MjData(model)
        mujoco.mj_kinematics(model, data)
        yield SceneDrawer(server, model, data), data, {"rcm": cue_color("rcm", 0)}
    finally:
        server.stop()


def test_the_drawer_sends_only_the_bodies_that_moved(model: mujoco.MjModel, drawn: tuple) -> None:
    drawer, data, colors = drawn
    snap = snapshot(model, data)
    assert drawer.update(snap, colors) == model.nbody - 1  # first update: every body
    assert drawer.update(snap, colors) == 0
    moved = snapshot(model, data)
    moved.body_pos[3] += 0.01
    assert drawer.update(moved, colors) == 1


def test_a_drift_below_a_pixel_is_sent_once_it_adds_up(model: mujoco.MjModel, drawn: tuple) -> None:
    drawer, data, colors = drawn
    drawer.update(snapshot(model, data), colors)
    sent = []
    for _ in range(10):  # 0.05 mm a frame: invisible alone, 0.5 mm in all
        data.xpos[3, 0] += 5e-5
        sent.append(drawer.update(snapshot(model, data), colors))
    assert 1 <= sum(sent) <= 3  # not every frame, but each time it has added up to 0.2 mm
