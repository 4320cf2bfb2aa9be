"""The scope description: parallel frames by default, the 30° oblique option and tracking with it."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.robot.arms import ARM_SPECS, ScopeMount, UrdfFile
from lapwrench.robot.description import (
    FRAME_C,
    FRAME_E,
    MAX_URDF_BYTES,
    RobotDescriptionError,
    ScopeGeometry,
    build_urdf,
)
from lapwrench.robot.model import RobotModel
from lapwrench.virtual import DEFAULT_Q0, project_points, run_virtual


def test_parallel_frames_by_default() -> None:
    m = RobotModel("panda")
    kin = m.kinematics(DEFAULT_Q0, np.zeros(7))
    np.testing.assert_allclose(kin.R_C, kin.R_E, atol=1e-12)
    np.testing.assert_allclose(kin.R_H, kin.R_E, atol=1e-12)
    np.testing.assert_allclose(kin.p_C, kin.p_E + 0.29 * kin.d_z, atol=1e-12)


def test_oblique_camera_looks_30_degrees_off_the_shaft() -> None:
    m = RobotModel("panda", ScopeGeometry(oblique_angle_deg=30.0))
    kin = m.kinematics(DEFAULT_Q0, np.zeros(7))
    angle = math.degrees(math.acos(kin.R_C[:, 2] @ kin.d_z))
    assert angle == pytest.approx(30.0, abs=1e-6)  # URDF text keeps 9 digits
    np.testing.assert_allclose(kin.R_C[:, 0], kin.R_E[:, 0], atol=1e-12)  # tilted about x_E
    np.testing.assert_allclose(kin.p_C, kin.p_E + 0.29 * kin.d_z, atol=1e-12)
    assert m.frame_pose(DEFAULT_Q0, FRAME_C).translation == pytest.approx(
        m.frame_pose(DEFAULT_Q0, FRAME_E).translation + 0.29 * kin.d_z
    )


def test_oblique_scope_tracks_in_its_own_camera_frame() -> None:
    cfg = load().replace(scope={"oblique_angle_deg": 30.0})
    ctrl = Controller(cfg)
    kin = ctrl.model.kinematics(DEFAULT_Q0, np.zeros(7))
    depth = 0.07
    point = kin.p_C + kin.R_C @ np.array([150.0 / cfg.camera.fx * depth, 0.0, depth])
    uv, vis = project_points(point[None], kin.p_C, kin.R_C, cfg.camera)
    assert vis[0] and math.hypot(uv[0, 0] - cfg.camera.u0, uv[0, 1] - cfg.camera.v0) == pytest.approx(150.0, abs=0.5)
    _, log = run_virtual(cfg, 3.0, instruments=lambda t: point[None], controller=ctrl)
    d = [math.hypot(p[0, 0] - cfg.camera.u0, p[0, 1] - cfg.camera.v0) for p in log.pixels if len(p)]
    assert d[-1] < cfg.tracking.epsilon1
    assert max(r.rcm_error for r in log.results) < 5e-4


# -- a robot description is checked before anything reads it ------------------------------------------
PANDA_URDF = ARM_SPECS["panda"].urdf_path().read_text()
FIRST_LIMIT = re.search(r"<limit [^>]*>", PANDA_URDF).group(0)  # type: ignore[union-attr]  # panda_joint1's


def _without_meshes(text: str) -> str:
    return re.sub(r"<(visual|collision)>.*?</\1>", "", text, flags=re.S)


def _with_limit(key: str, value: str) -> str:
    return _without_meshes(PANDA_URDF.replace(FIRST_LIMIT, re.sub(f'{key}="[^"]*"', f'{key}="{value}"', FIRST_LIMIT)))


def _arm_from(monkeypatch: pytest.MonkeyPatch, path: Path, **changes: object) -> str:
    """Register a panda whose description is the file ``path`` (changed by ``changes``); its name."""
    spec = dataclasses.replace(ARM_SPECS["panda"], name="test_arm", description=UrdfFile(path), **changes)
    monkeypatch.setitem(ARM_SPECS, "test_arm", spec)
    return "test_arm"


@pytest.mark.parametrize(("text", "words"), [
    (None, "cannot read .*No such file"),
    ("", "cannot parse"),
    (PANDA_URDF[: len(PANDA_URDF) // 2], "cannot parse"),
    (bytes(range(256)) * 4, "cannot parse"),
    ("<html></html>", "not a URDF's <robot>"),
    (_with_limit("lower", "nan"), "panda_joint1' limit lower='nan' is not a finite number"),
    (_with_limit("upper", "inf"), "limit upper='inf' is not a finite number"),
    (_with_limit("lower", "abc"), "limit lower='abc' is not a finite number"),
    (_with_limit("lower", "3.0"), "limit lower=3 is not below upper=2.8973"),
    (_with_limit("velocity", "0"), "limit velocity=0 is not positive"),
    (_with_limit("velocity", "-1"), "limit velocity=-1 is not positive"),
    (_without_meshes(PANDA_URDF.replace('type="revolute"', 'type="floating"', 1)), "'floating'; an arm joint"),
    (_without_meshes(PANDA_URDF.replace('type="revolute"', 'type="continuous"', 1)), "'continuous'; an arm joint"),
    (_without_meshes(PANDA_URDF.replace('name="panda_joint7" type="revolute"', 'name="panda_joint7" type="fixed"')),
     "6 moving joints"),
    (_without_meshes(PANDA_URDF.replace('<child link="panda_link2"/>', '<child link="panda_link1"/>')),
     "more than one parent"),
    (_without_meshes(PANDA_URDF).replace("</robot>", '<joint name="back" type="fixed"><parent link="panda_link3"/>'
                                         '<child link="panda_link0"/></joint></robot>'), "form a loop"),
    (_without_meshes(PANDA_URDF).replace("</robot>", '<link name="m"><visual><geometry><mesh filename="/no/such.stl"/>'
                                         '</geometry></visual></link></robot>'),
     "mesh file '/no/such.stl' does not exist"),
], ids=["missing", "empty", "truncated", "binary", "not-urdf", "nan-lower", "inf-upper", "text-lower", "swapped",
        "zero-velocity", "negative-velocity", "floating", "continuous", "six-joints", "two-parents", "cycle",
        "missing-mesh"])
def test_a_bad_description_is_one_error_naming_the_file(monkeypatch: pytest.MonkeyPatch, tmp_path: Path,
                                                         text: str | bytes | None, words: str) -> None:
    path = tmp_path / "arm.urdf"
    if isinstance(text, bytes):
        path.write_bytes(text)
    elif text is not None:
        path.write_text(text)
    kind = _arm_from(monkeypatch, path)
    with pytest.raises(RobotDescriptionError, match=words) as err:
        RobotModel(kind)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_a_description_without_the_flange_link_is_refused(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    path = tmp_path / "arm.urdf"
    path.write_text(_without_meshes(PANDA_URDF))
    kind = _arm_from(monkeypatch, path, mount=ScopeMount("no_such_flange"))
    with pytest.raises(RobotDescriptionError, match="no link 'no_such_flange'"):
        build_urdf(kind)


def test_a_huge_description_is_refused_before_it_is_parsed(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    path = tmp_path / "arm.urdf"
    path.write_text(PANDA_URDF.replace("</robot>", "<!--" + "x" * MAX_URDF_BYTES + "--></robot>"))
    with pytest.raises(RobotDescriptionError, match="a robot description is at most"):
        build_urdf(_arm_from(monkeypatch, path))


def test_a_good_description_of_ones_own_loads(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    path = tmp_path / "arm.urdf"
    path.write_text(_without_meshes(PANDA_URDF))
    m = RobotModel(_arm_from(monkeypatch, path))
    np.testing.assert_array_equal(m.limits.position_lower, RobotModel("panda").limits.position_lower)
