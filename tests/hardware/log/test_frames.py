"""Frame transforms in the run log, from the measured joints when a model is given."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hardware.log.support import Q0, tf_messages, write

from lapwrench.hardware import log as runlog
from lapwrench.hardware.log import (
    iter_messages,
    log_topics,
)
from lapwrench.robot.model import RobotModel


def test_transforms_from_the_measured_joints_when_a_model_is_given(tmp_path: Path, panda: RobotModel) -> None:
    path = tmp_path / "run.mcap"
    write(path, 200, model=panda)  # 0.2 s of cycles: transforms at 100 Hz of session time
    tfs = tf_messages(path)
    assert len(tfs) == 20
    first = {t["child_frame_id"]: t for t in tfs[0]["transforms"]}
    last = {t["child_frame_id"]: t for t in tfs[-1]["transforms"]}
    # the fixed frames (flange, scope frames on it) in the first set, the moving ones in every set
    assert {"lap_E", "lap_H", "lap_C", "panda_link8", "lap_R", "lap_G", "panda_link1", "panda_link7"} <= set(first)
    assert set(last) == {f"panda_link{j}" for j in range(1, 8)} | {"lap_R", "lap_G"}
    assert first["lap_E"]["parent_frame_id"] == "panda_link8" and first["lap_C"]["parent_frame_id"] == "lap_E"
    assert last["panda_link1"]["parent_frame_id"] == "panda_link0" and last["lap_R"]["parent_frame_id"] == "panda_link0"
    t_R = last["lap_R"]["translation"]
    assert [t_R["x"], t_R["y"], t_R["z"]] == pytest.approx([0.45, 0.0, 0.25])
    # the scope pose is the forward kinematics of the measured q of the cycle it was written with
    kin = panda.kinematics(Q0 + 1e-3 * 190, np.zeros(7))
    pose = [m for _, m in iter_messages(path, [runlog.POSE_TOPIC])][-1]
    p = pose["pose"]["position"]
    assert pose["frame_id"] == "panda_link0" and [p["x"], p["y"], p["z"]] == pytest.approx(kin.p_E, abs=1e-9)
    o = pose["pose"]["orientation"]
    x, y, z, w = o["x"], o["y"], o["z"], o["w"]
    R = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])  # fmt: skip
    assert np.allclose(R, kin.R_E, atol=1e-9)
    # wrench arrows: the interaction force (-5 N along z) drawn at H, 1 cm per N
    scene = [m for _, m in iter_messages(path, [runlog.WRENCH_TOPIC])][-1]
    ent = {e["id"]: e for e in scene["entities"]}
    (arrow,) = ent["interaction"]["arrows"]
    assert arrow["shaft_length"] + arrow["head_length"] == pytest.approx(0.05)
    h = arrow["pose"]["position"]
    assert [h["x"], h["y"], h["z"]] == pytest.approx(kin.p_H, abs=1e-9)
    assert ent["tracking"]["arrows"] == []  # a zero force: no arrow
    # without a model: no transforms, no pose, no arrows (joint states only)
    bare = tmp_path / "bare.mcap"
    write(bare, 200)
    topics = log_topics(bare)
    assert (
        runlog.TF_TOPIC not in topics
        and runlog.WRENCH_TOPIC not in topics
        and topics[runlog.JOINTS_TOPIC].messages == 20
    )
