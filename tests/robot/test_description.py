"""The scope description: parallel frames by default, the 30° oblique option and tracking with it."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import os
import re
import threading
from pathlib import Path

import numpy as np
import pytest

from lapwrench.config import load
from lapwrench.controller import Controller
from lapwrench.robot.arms import ARM_SPECS, ScopeMount, UrdfFile
from lapwrench.robot.description import (
    FRAME_C,
    FRAME_E,
    MAX_LINKS,
    MAX_MESH_BYTES,
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


# -- the numbers of a description are checked before Pinocchio reads them -----------------------------
LINK3 = re.search(r'<link name="panda_link3">.*?</link>', PANDA_URDF, flags=re.S).group(0)  # type: ignore[union-attr]
JOINT2 = re.search(r'<joint name="panda_joint2".*?</joint>', PANDA_URDF, flags=re.S).group(0)  # type: ignore[union-attr]


def _link3(pattern: str, replacement: str) -> str:
    """The mesh-free Panda with ``pattern`` replaced (once) in panda_link3's ``<inertial>``."""
    return _without_meshes(PANDA_URDF.replace(LINK3, re.sub(pattern, replacement, LINK3, count=1)))


def _joint2(pattern: str, replacement: str) -> str:
    return _without_meshes(PANDA_URDF.replace(JOINT2, re.sub(pattern, replacement, JOINT2, count=1)))


@pytest.mark.parametrize(("text", "words"), [
    # urdfdom printed several lines and dropped the link's inertia: Pinocchio loaded a different arm
    (_link3(r'<mass value="[^"]*"', '<mass value="nan"'), r"link 'panda_link3' mass value='nan' is not a finite"),
    (_link3(r'<mass value="[^"]*"', '<mass value="heavy"'), r"mass value='heavy' is not a finite"),
    (_link3(r'ixx="[^"]*"', 'ixx="inf"'), r"inertia ixx='inf' is not a finite"),
    (_link3(r"<mass [^>]*>", ""), r"link 'panda_link3' has an <inertial> without <mass value"),
    (_link3(r'ixx="[^"]*"', ""), r"link 'panda_link3' has an <inertia> without ixx"),
    (_link3(r'(<inertial>\s*<origin [^>]*xyz=")[^"]*"', r'\1nan 0 0"'), r"origin xyz='nan 0 0' is not 3 finite"),
    # Pinocchio loaded these: a mass matrix that is not positive definite, or 1e301 large
    (_link3(r'<mass value="[^"]*"', '<mass value="-3"'), r"link 'panda_link3' mass -3 kg is not in \[0, 1000\]"),
    (_link3(r'<mass value="[^"]*"', '<mass value="1e300"'), r"mass 1e\+300 kg is not in \[0, 1000\]"),
    (_link3(r'ixy="[^"]*"', 'ixy="10"'), r"link 'panda_link3' inertia is not positive semi-definite"),
    (_link3(r'ixx="[^"]*"', 'ixx="-1"'), r"inertia is not positive semi-definite"),
    (_link3(r'ixx="[^"]*"', 'ixx="1"'), r"principal moments .* break the triangle inequality"),
    (_link3(r'ixx="[^"]*"', 'ixx="1e300"'), r"inertia ixx=1e\+300 kg m\^2 is beyond 1000"),
    # an origin of 1e300 m gave NaN kinematics; a zero axis a singular mass matrix (and an IndexError later)
    (_joint2(r'xyz="[^"]*"', 'xyz="1e300 0 0"'), r"joint 'panda_joint2' origin xyz='1e300 0 0' is beyond 10 m"),
    (_joint2(r'rpy="[^"]*"', 'rpy="nan 0 0"'), r"joint 'panda_joint2' origin rpy='nan 0 0' is not 3 finite"),
    (_joint2(r'<axis xyz="[^"]*"', '<axis xyz="0 0 0"'), r"joint 'panda_joint2' axis xyz='0 0 0' is not a direction"),
    (_joint2(r'<axis xyz="[^"]*"', '<axis xyz="0 0 1e-300"'), r"axis xyz='0 0 1e-300' is not a direction"),
    (_joint2(r'<axis xyz="[^"]*"', '<axis xyz="0 1"'), r"axis xyz='0 1' is not 3 finite numbers"),
    # urdfdom printed its own lines before Pinocchio's refusal
    (_without_meshes(PANDA_URDF).replace("</robot>", '<link name="panda_link3"/></robot>'),
     r"link 'panda_link3' is defined twice"),
    (_without_meshes(PANDA_URDF).replace("</robot>", '<link name="x"/><joint name="panda_joint8" type="fixed">'
                                         '<parent link="panda_link0"/><child link="x"/></joint></robot>'),
     r"joint 'panda_joint8' is defined twice"),
    (_without_meshes(PANDA_URDF).replace("</robot>", '<link name="orphan"/></robot>'),
     r"2 links have no parent \('orphan', 'panda_link0'\); a description is one tree"),
], ids=["mass-nan", "mass-text", "inertia-inf", "no-mass", "no-ixx", "com-nan", "mass-negative", "mass-huge",
        "inertia-not-psd", "inertia-negative", "inertia-triangle", "inertia-huge", "origin-huge", "rpy-nan",
        "axis-zero", "axis-underflow", "axis-short", "duplicate-link", "duplicate-joint", "two-roots"])
def test_bad_numbers_in_a_description_are_one_error_naming_the_file(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path, capfd: pytest.CaptureFixture[str], text: str, words: str
) -> None:
    path = tmp_path / "arm.urdf"
    path.write_text(text)
    with pytest.raises(RobotDescriptionError, match=words) as err:
        RobotModel(_arm_from(monkeypatch, path))
    assert str(path) in str(err.value) and "\n" not in str(err.value)
    assert capfd.readouterr().err == ""  # refused before urdfdom could print its own lines


def test_a_description_that_is_a_fifo_is_refused_without_waiting_for_a_writer(
    monkeypatch: pytest.MonkeyPatch, tmp_path: Path
) -> None:
    """``ET.parse`` opened a FIFO and waited for a writer forever (and read a writer's endless stream)."""
    fifo = tmp_path / "arm.urdf"
    os.mkfifo(fifo)

    def writer() -> None:  # without the check, this writer lets the old reader go on, to a loaded model
        with contextlib.suppress(OSError), fifo.open("w") as f:
            f.write(_without_meshes(PANDA_URDF))

    thread = threading.Thread(target=writer, daemon=True)
    thread.start()
    try:
        with pytest.raises(RobotDescriptionError, match=r"arm\.urdf is not a regular file"):
            build_urdf(_arm_from(monkeypatch, fifo))
    finally:
        os.close(os.open(fifo, os.O_RDONLY | os.O_NONBLOCK))  # lets the writer's open return (then EPIPE)
        thread.join(5.0)


def test_the_shipped_descriptions_pass_the_checks() -> None:
    for kind in ARM_SPECS:
        assert "<robot" in build_urdf(kind)


def test_a_description_with_too_many_links_is_refused(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """A chain of 6000 fixed links (640 kB) crashed the process inside urdfdom (SIGSEGV); 20 000 side links took
    Pinocchio 11 s."""
    parents = ["panda_link0"] + [f"c{i}" for i in range(MAX_LINKS)]
    chain = "".join(f'<link name="c{i}"/><joint name="cj{i}" type="fixed"><parent link="{parents[i]}"/>'
                    f'<child link="c{i}"/></joint>' for i in range(MAX_LINKS))
    path = tmp_path / "arm.urdf"
    path.write_text(_without_meshes(PANDA_URDF).replace("</robot>", chain + "</robot>"))
    words = rf"arm\.urdf: \d+ links; a robot description has at most {MAX_LINKS}"
    with pytest.raises(RobotDescriptionError, match=words):
        build_urdf(_arm_from(monkeypatch, path))


def test_a_loop_below_the_flange_is_stripped_with_the_gripper(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """Every joint that hangs from a gripper's link goes with it, a loop's too (each one was removed as often
    as the loop was walked: a ValueError, or a joint left between two removed links)."""
    loop = ('<link name="g1"/><link name="g2"/><joint name="a" type="fixed"><parent link="panda_hand"/>'
            '<child link="g1"/></joint><joint name="b" type="fixed"><parent link="g1"/><child link="g2"/></joint>'
            '<joint name="c" type="fixed"><parent link="g2"/><child link="g1"/></joint>'
            '<joint name="d" type="fixed"><parent link="g2"/><child link="panda_link8"/></joint>')
    path = tmp_path / "arm.urdf"
    path.write_text(_without_meshes(PANDA_URDF).replace("</robot>", loop + "</robot>"))
    urdf = build_urdf(_arm_from(monkeypatch, path))
    assert not re.search(r'name="(g1|g2|a|b|c|d)"', urdf)
    assert RobotModel(_arm_from(monkeypatch, path)).nq == 7


def test_a_mesh_must_be_a_mesh_file_of_bounded_size(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """MuJoCo reads a mesh whole and ``--foxglove`` serves each one the URDF names to any client: a description
    naming /etc/passwd as a mesh had it served."""
    def with_mesh(name: str) -> str:
        return _without_meshes(PANDA_URDF).replace(
            '<link name="panda_link3">', f'<link name="panda_link3"><visual><geometry><mesh filename="{name}"/>'
            '</geometry></visual>')

    path = tmp_path / "arm.urdf"
    path.write_text(with_mesh("/etc/passwd"))
    with pytest.raises(RobotDescriptionError, match=r"mesh file '/etc/passwd' is not a mesh \(\.stl, \.dae"):
        build_urdf(_arm_from(monkeypatch, path))
    huge = tmp_path / "huge.STL"
    with huge.open("wb") as f:
        f.truncate(MAX_MESH_BYTES + 1)  # sparse: no disk used
    path.write_text(with_mesh(str(huge)))
    with pytest.raises(RobotDescriptionError, match=rf"huge\.STL' is over {MAX_MESH_BYTES} bytes"):
        build_urdf(_arm_from(monkeypatch, path))
    (tmp_path / "small.stl").write_bytes(b"solid x\nendsolid x\n")
    path.write_text(with_mesh("small.stl"))  # relative to the description
    assert str(tmp_path / "small.stl") in build_urdf(_arm_from(monkeypatch, path))


def test_deeply_nested_elements_are_refused(monkeypatch: pytest.MonkeyPatch, tmp_path: Path) -> None:
    """ET.tostring recurses: 1000 nested elements (6 kB) were a RecursionError traceback."""
    path = tmp_path / "arm.urdf"
    nested = LINK3.replace("</link>", "<a>" * 1000 + "</a>" * 1000 + "</link>")
    path.write_text(_without_meshes(PANDA_URDF.replace(LINK3, nested)))
    with pytest.raises(RobotDescriptionError, match=r"arm\.urdf: elements nested deeper than \d+; a URDF nests 5"):
        build_urdf(_arm_from(monkeypatch, path))
