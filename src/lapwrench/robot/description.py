"""The robot description shared by the controller (Pinocchio) and the simulator (MuJoCo).

The arm URDF comes from a packaged robot description, named by the arm's spec
(:mod:`lapwrench.robot.arms`: ``example-robot-data`` for the Panda, UR5 and xArm7, ``franky-sim`` for
the FR3). The gripper is removed and a laparoscope is rigidly mounted on the flange as extra URDF
links, so that Pinocchio and MuJoCo load the *same* text.

Frames (paper Sec. II-B). All are parallel to {E} by default:

- ``lap_E``: end-effector {E}, on the flange at the spec's scope mount; +z runs along the shaft.
- ``lap_H``: handle {H}, where the F/T sensor sits, ``handle_offset`` along +z from {E}.
- ``lap_grip``: the grip beyond the sensor, on {H} (its mass ``grip_mass`` at ``grip_com`` in {H}): what
  the hand holds, so the sensor reads its weight with the hand's wrench.
- ``lap_C``: camera {C} at the scope tip, ``L`` along +z. With an oblique scope it is rotated
  about x_E by ``oblique_angle_deg`` (the paper's convention is the parallel frame).
- ``lap_tip``: the distal end of the shaft (same origin as {C}, always parallel to {E}).
"""

from __future__ import annotations

import math
import os
import re
import stat
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lapwrench.config import ScopeConfig
from lapwrench.robot.arms import ARM_SPECS, MAX_JOINTS, ArmSpec, RobotDescriptionError, arm_spec
from lapwrench.robot_kinds import ROBOT_KINDS

RobotKind = str
"""A registered arm's name (:data:`~lapwrench.robot_kinds.ROBOT_KINDS`); checked against the registry."""

FRAME_E = "lap_E"
FRAME_H = "lap_H"
FRAME_GRIP = "lap_grip"
FRAME_C = "lap_C"
FRAME_TIP = "lap_tip"

__all__ = [
    "ARM_SPECS", "FRAME_C", "FRAME_E", "FRAME_GRIP", "FRAME_H", "FRAME_TIP", "MAX_JOINTS", "MAX_URDF_BYTES",
    "ROBOT_KINDS", "ArmSpec", "RobotDescriptionError", "RobotKind", "ScopeGeometry", "arm_spec", "arm_urdf_path",
    "build_urdf", "check_description",
]


@dataclass(frozen=True)
class ScopeGeometry:
    """Laparoscope assembly mounted on the flange.

    ``length`` is the paper's L (Sec. IV-A, 0.29 m). Masses are those of a typical 10 mm scope,
    a handle with a HEX-E class F/T sensor and a mounting adapter.
    """

    length: float = 0.29
    shaft_diameter: float = 0.010
    shaft_mass: float = 0.25
    handle_offset: float = 0.04
    handle_mass: float = 0.45  # on the flange side of the F/T sensor (0.55 kg with the grip)
    handle_radius: float = 0.02
    handle_length: float = 0.06
    oblique_angle_deg: float = 0.0
    grip_mass: float = 0.1  # beyond the F/T sensor: the sensor reads its weight
    grip_com: tuple[float, float, float] = (0.0, 0.0, 0.01)  # in {H}

    @classmethod
    def from_config(cls, scope: ScopeConfig) -> ScopeGeometry:
        """The geometry a configuration's ``scope`` section describes (other fields: defaults)."""
        return cls(length=scope.length, handle_offset=scope.handle_offset, oblique_angle_deg=scope.oblique_angle_deg,
                   grip_mass=scope.grip_mass, grip_com=tuple(scope.grip_com))  # type: ignore[arg-type]

    def __post_init__(self) -> None:
        for name in ("length", "shaft_diameter", "shaft_mass", "handle_mass", "handle_radius", "handle_length"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"scope.{name} must be a positive finite number, got {value!r}")
        if not (0.0 <= self.handle_offset < self.length):
            raise ValueError(f"scope.handle_offset must lie in [0, length), got {self.handle_offset!r}")
        if not (0.0 <= self.oblique_angle_deg < 90.0):
            raise ValueError(f"scope.oblique_angle_deg must lie in [0, 90), got {self.oblique_angle_deg!r}")
        if not (math.isfinite(self.grip_mass) and self.grip_mass >= 0.0):
            raise ValueError(f"scope.grip_mass must be a finite number >= 0, got {self.grip_mass!r}")
        if len(self.grip_com) != 3 or not all(math.isfinite(c) and abs(c) <= 0.2 for c in self.grip_com):
            raise ValueError(f"scope.grip_com must be 3 finite numbers within 0.2 m, got {self.grip_com!r}")


def arm_urdf_path(kind: RobotKind) -> Path:
    """Path of the packaged arm URDF for ``kind`` (its spec's ``description``)."""
    try:
        spec = arm_spec(kind)
    except ValueError as exc:
        raise RobotDescriptionError(str(exc)) from None
    return spec.urdf_path()


def _resolve_mesh_paths(root: ET.Element, urdf_path: Path) -> None:
    """Turn ``package://`` and relative mesh names into absolute paths."""
    share = urdf_path.parent
    while share.name and share.name != "share" and share.parent != share:
        share = share.parent
    for mesh in root.iter("mesh"):
        name = mesh.get("filename", "")
        if name.startswith("package://"):
            rel = name[len("package://") :]
            candidates = [share / rel, urdf_path.parent / rel, urdf_path.parent.parent / Path(rel).name]
            candidates += [urdf_path.parent / Path(*Path(rel).parts[1:])]
            found = next((c for c in candidates if c.is_file()), candidates[0])
            mesh.set("filename", str(found))
        elif name and not Path(name).is_absolute():
            mesh.set("filename", str((urdf_path.parent / name).resolve()))


MAX_URDF_BYTES = 4 * 1024 * 1024
"""The largest robot description read (the shipped ones are 10-17 kB)."""
MAX_DEPTH = 32  # elements nested in a description (robot, link, visual, geometry, mesh: 5)
_MOVING = ("revolute", "prismatic")  # one coordinate each (a continuous joint has two in Pinocchio)


def _read_description(path: Path) -> ET.Element:
    """The parsed URDF at ``path``; :class:`RobotDescriptionError` naming the file when it cannot be read.

    Only a regular file is read, and at most :data:`MAX_URDF_BYTES` of it: a FIFO kept ``ET.parse`` waiting
    for a writer (then reading its stream without end). Opened without blocking, then checked on the open file.
    """
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
        with os.fdopen(fd, "rb") as f:
            if not stat.S_ISREG(os.fstat(f.fileno()).st_mode):
                raise RobotDescriptionError(f"{path} is not a regular file")
            data = f.read(MAX_URDF_BYTES + 1)
        if len(data) > MAX_URDF_BYTES:
            raise RobotDescriptionError(f"{path}: over {MAX_URDF_BYTES} bytes; a robot description is at most "
                                        f"{MAX_URDF_BYTES}")
        root = ET.fromstring(data)
    except ET.ParseError as exc:
        raise RobotDescriptionError(f"cannot parse {path}: {exc}") from exc
    except OSError as exc:
        raise RobotDescriptionError(f"cannot read {path}: {exc.strerror or exc}") from exc
    if root.tag != "robot":
        raise RobotDescriptionError(f"{path}: the root element is <{root.tag[:40]}>, not a URDF's <robot>")
    stack = [(root, 1)]  # ET.tostring recurses: 1000 nested elements were a RecursionError
    while stack:
        element, depth = stack.pop()
        if depth > MAX_DEPTH:
            raise RobotDescriptionError(f"{path}: elements nested deeper than {MAX_DEPTH}; a URDF nests 5 deep")
        stack.extend((child, depth + 1) for child in element)
    return root


# The numbers urdfdom reads (3 per vector attribute, else 1): a bad one made it print several lines and then
# drop the element (a link's inertia: a different arm, silently) or refuse the whole model.
_VECTORS = {"origin": ("xyz", "rpy"), "axis": ("xyz",), "box": ("size",), "mesh": ("scale",)}
_SCALARS = {"mass": ("value",), "inertia": ("ixx", "ixy", "ixz", "iyy", "iyz", "izz"), "cylinder": ("radius", "length"),
            "sphere": ("radius",), "dynamics": ("damping", "friction")}
MAX_LINK_MASS = 1000.0  # kg; the heaviest shipped link weighs 8.4 kg (1e300 kg: a mass matrix of condition 1e301)
MAX_LINK_INERTIA = 1000.0  # kg m^2, each entry of a link's inertia
MAX_LINKS = 1000  # links, and joints (the shipped descriptions have 13-25): a chain of 6000 crashed urdfdom (SIGSEGV)
MESH_SUFFIXES = (".stl", ".dae", ".obj", ".ply", ".msh", ".glb", ".gltf")
MAX_MESH_BYTES = 64 * 1024 * 1024  # the shipped meshes are at most 2 MB
MAX_OFFSET = 10.0  # m, each coordinate of an origin (an arm reaches ~1 m; 1e300 m gave NaN kinematics)
_NUMBER = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?")  # a decimal number, as urdfdom reads


def _floats(text: str | None) -> list[float]:
    """The numbers of an attribute's text; NaN for anything that is not a finite decimal number."""
    return [float(word) if _NUMBER.fullmatch(word) else math.nan for word in (text or "").split()]


def _numbers_problem(element: ET.Element) -> str:
    """What is wrong with the numbers urdfdom reads in ``element`` and below ("" when nothing)."""
    for el in element.iter():
        for attr in _VECTORS.get(el.tag, ()):
            raw = el.get(attr)
            if raw is not None and not (len(v := _floats(raw)) == 3 and all(math.isfinite(x) for x in v)):
                return f"{el.tag} {attr}={raw[:40]!r} is not 3 finite numbers"
        for attr in _SCALARS.get(el.tag, ()):
            raw = el.get(attr)
            if raw is not None and not (len(v := _floats(raw)) == 1 and math.isfinite(v[0])):
                return f"{el.tag} {attr}={raw[:20]!r} is not a finite number"
        if el.tag == "origin" and max(map(abs, _floats(el.get("xyz"))), default=0.0) > MAX_OFFSET:
            return f"origin xyz={el.get('xyz', '')[:40]!r} is beyond {MAX_OFFSET:g} m"
    return ""


def _inertial_problem(link: ET.Element) -> str:
    """What is wrong with a link's ``<inertial>`` ("" when nothing): its mass in [0, :data:`MAX_LINK_MASS`], its
    inertia bounded, positive semi-definite and a body's (each principal moment at most the sum of the others)."""
    inertial = link.find("inertial")
    if inertial is None:
        return ""
    mass, inertia = inertial.find("mass"), inertial.find("inertia")
    if mass is None or mass.get("value") is None:
        return "has an <inertial> without <mass value=...>"
    m = float(mass.get("value", ""))  # finite: _numbers_problem ran first
    if not 0.0 <= m <= MAX_LINK_MASS:
        return f"mass {m:g} kg is not in [0, {MAX_LINK_MASS:g}]"
    names = _SCALARS["inertia"]
    missing = [n for n in names if inertia is None or inertia.get(n) is None]
    if missing:
        return f"has an <inertia> without {', '.join(missing)}"
    v = {n: float(inertia.get(n, "")) for n in names}  # type: ignore[union-attr]
    big = next((n for n in names if abs(v[n]) > MAX_LINK_INERTIA), None)
    if big:
        return f"inertia {big}={v[big]:g} kg m^2 is beyond {MAX_LINK_INERTIA:g}"
    matrix = np.array([[v["ixx"], v["ixy"], v["ixz"]], [v["ixy"], v["iyy"], v["iyz"]], [v["ixz"], v["iyz"], v["izz"]]])
    moments = np.linalg.eigvalsh(matrix)
    tolerance = 1e-9 * max(float(np.abs(moments).max()), 1e-12)
    if moments[0] < -tolerance:
        return f"inertia is not positive semi-definite (principal moments {np.round(moments, 6).tolist()})"
    if moments[0] + moments[1] < moments[2] - tolerance:
        return f"inertia's principal moments {np.round(moments, 6).tolist()} break the triangle inequality"
    return ""


def _mesh_problem(mesh: Path) -> str:
    """What is wrong with a mesh file ("" when nothing): MuJoCo reads it whole, and ``--foxglove`` serves it to
    any client (a URDF naming /etc/passwd as a mesh had it served)."""
    if not mesh.is_file():
        return "does not exist"
    if mesh.suffix.lower() not in MESH_SUFFIXES:
        return f"is not a mesh ({', '.join(MESH_SUFFIXES)})"
    return f"is over {MAX_MESH_BYTES} bytes" if mesh.stat().st_size > MAX_MESH_BYTES else ""


def _limit_problem(joint: ET.Element) -> str:
    """What is wrong with a moving joint's ``<limit>`` ("" when nothing)."""
    limit = joint.find("limit")
    if limit is None:
        return "has no <limit>"
    values = {key: v[0] if len(v := _floats(limit.get(key))) == 1 else math.nan
              for key in ("lower", "upper", "velocity", "effort")}
    bad = next((key for key, value in values.items() if not math.isfinite(value)), None)
    if bad is not None:
        return f"limit {bad}={limit.get(bad, 'missing')[:20]!r} is not a finite number"
    if not values["lower"] < values["upper"]:
        return f"limit lower={values['lower']:g} is not below upper={values['upper']:g}"
    for key in ("velocity", "effort"):
        if not values[key] > 0.0:
            return f"limit {key}={values[key]:g} is not positive"
    return ""


def check_description(root: ET.Element, path: Path, spec: ArmSpec) -> None:
    """The arm's URDF (gripper removed) against its spec, before Pinocchio or MuJoCo reads it: one
    :class:`RobotDescriptionError` naming the file and the first problem (over :data:`MAX_LINKS` links or joints,
    one defined twice, a missing base or flange link, a number urdfdom would not read or an origin beyond
    :data:`MAX_OFFSET`, a mass or inertia no body has, a link with two parents (a loop), moving joints other
    than the spec's, a joint type other than revolute/prismatic, a zero axis, a non-finite, swapped or
    non-positive limit, a mesh file that does not exist, links outside the one tree)."""
    for tag in ("link", "joint"):
        named: set[str | None] = set()
        if len(elements := root.findall(tag)) > MAX_LINKS:
            raise RobotDescriptionError(f"{path}: {len(elements)} {tag}s; a robot description has at most {MAX_LINKS}")
        for el in elements:
            if el.get("name") in named:
                raise RobotDescriptionError(f"{path}: {tag} {str(el.get('name'))[:60]!r} is defined twice")
            named.add(el.get("name"))
    links = {link.get("name") for link in root.findall("link")}
    for needed in (spec.base_link, spec.mount.link):
        if needed not in links:
            raise RobotDescriptionError(f"{path}: no link {needed!r} (the {spec.name} spec's base or flange)")
    for element in root.findall("link"):
        problem = _numbers_problem(element) or _inertial_problem(element)
        if problem:
            raise RobotDescriptionError(f"{path}: link {str(element.get('name'))[:60]!r} {problem}")
    parent_of: dict[str | None, str | None] = {}
    moving: list[str] = []
    for joint in root.findall("joint"):
        full = str(joint.get("name"))
        name = full[:60]  # quoted in the errors below
        parent, child = joint.find("parent"), joint.find("child")
        ends = (None if parent is None else parent.get("link"), None if child is None else child.get("link"))
        if not all(end in links for end in ends):
            raise RobotDescriptionError(f"{path}: joint {name!r} connects links that are not defined: "
                                        f"{tuple(str(e)[:60] for e in ends)}")
        if ends[1] in parent_of:
            raise RobotDescriptionError(f"{path}: link {str(ends[1])[:60]!r} has more than one parent (a loop)")
        parent_of[ends[1]] = ends[0]
        problem = _numbers_problem(joint)
        if problem:
            raise RobotDescriptionError(f"{path}: joint {name!r} {problem}")
        kind = joint.get("type")
        if kind == "fixed":
            continue
        if kind not in _MOVING:
            raise RobotDescriptionError(f"{path}: joint {name!r} is {str(kind)[:20]!r}; an arm joint is revolute "
                                        "or prismatic")
        axis = joint.find("axis")  # absent: x; Pinocchio normalises it, but (0, 0, 0) stays a dead joint
        if axis is not None and math.hypot(*_floats(axis.get("xyz", "1 0 0"))) < 1e-6:
            raise RobotDescriptionError(f"{path}: joint {name!r} axis xyz={axis.get('xyz', '')[:40]!r} is not a "
                                        "direction")
        problem = _limit_problem(joint)
        if problem:
            raise RobotDescriptionError(f"{path}: joint {name!r} {problem}")
        moving.append(full)
    link: str | None = spec.mount.link
    seen: set[str | None] = set()
    while link in parent_of:  # up from the flange to the root
        if link in seen:
            raise RobotDescriptionError(f"{path}: the joints above link {str(link)[:60]!r} form a loop")
        seen.add(link)
        link = parent_of[link]
    if sorted(moving) != sorted(spec.joint_names):
        shown = [m[:60] for m in moving[:12]]
        raise RobotDescriptionError(f"{path}: {len(moving)} moving joints {shown}; the {spec.name} spec "
                                    f"has {spec.n_joints}: {list(spec.joint_names)}")
    for mesh in root.iter("mesh"):
        name = mesh.get("filename", "")
        problem = _mesh_problem(Path(name))
        if problem:
            raise RobotDescriptionError(f"{path}: mesh file {name[:200]!r} {problem}")
    roots = sorted(str(n)[:60] for n in links - set(parent_of))
    if len(roots) != 1:
        raise RobotDescriptionError(f"{path}: {len(roots)} links have no parent {tuple(roots[:4])}; a description is "
                                    "one tree")


def _strip_below(root: ET.Element, keep_link: str) -> None:
    """Remove every link and joint hanging below ``keep_link`` (gripper, fingers, TCP), and the transmissions and
    Gazebo blocks; in one pass over the elements (removing each one by one took quadratic time: 4 s for 20 000)."""
    children: dict[str, list[tuple[ET.Element, str]]] = {}
    for joint in root.findall("joint"):
        parent, child = joint.find("parent"), joint.find("child")
        if parent is not None and child is not None:
            children.setdefault(parent.get("link", ""), []).append((joint, child.get("link", "")))
    doomed_links: set[str] = set()
    doomed: set[ET.Element] = set()
    stack = [keep_link]
    while stack:
        for joint, child_link in children.get(stack.pop(), []):
            doomed.add(joint)
            if child_link not in doomed_links and child_link != keep_link:  # a loop below the flange: each once
                doomed_links.add(child_link)
                stack.append(child_link)
    root[:] = [el for el in root if el not in doomed and el.tag not in ("transmission", "gazebo")
               and not (el.tag == "link" and el.get("name") in doomed_links)]


def _cylinder_inertia(mass: float, radius: float, length: float) -> dict[str, str]:
    ixx = mass * (3.0 * radius**2 + length**2) / 12.0
    izz = 0.5 * mass * radius**2
    return {"ixx": f"{ixx:.9g}", "iyy": f"{ixx:.9g}", "izz": f"{izz:.9g}", "ixy": "0", "ixz": "0", "iyz": "0"}


def _add_link(root: ET.Element, name: str, parent: str, xyz: tuple[float, float, float],
              rpy: tuple[float, float, float] = (0.0, 0.0, 0.0), *, mass: float = 0.0, radius: float = 0.0,
              length: float = 0.0, com_z: float = 0.0, com: tuple[float, float, float] | None = None,
              shape: bool = True) -> None:
    """A link on a fixed joint; with ``mass``, a cylinder's inertia at ``com`` (default (0, 0, com_z)),
    drawn as that cylinder unless not ``shape``."""
    link = ET.SubElement(root, "link", name=name)
    if mass > 0.0:
        at = " ".join(f"{c:.9g}" for c in (com or (0.0, 0.0, com_z)))
        inertial = ET.SubElement(link, "inertial")
        ET.SubElement(inertial, "origin", xyz=at, rpy="0 0 0")
        ET.SubElement(inertial, "mass", value=f"{mass:.9g}")
        ET.SubElement(inertial, "inertia", _cylinder_inertia(mass, radius, length))
        for tag in ("visual", "collision") if shape else ():
            el = ET.SubElement(link, tag)
            ET.SubElement(el, "origin", xyz=at, rpy="0 0 0")
            geom = ET.SubElement(el, "geometry")
            ET.SubElement(geom, "cylinder", radius=f"{radius:.9g}", length=f"{length:.9g}")
    joint = ET.SubElement(root, "joint", name=f"{name}_joint", type="fixed")
    ET.SubElement(joint, "origin", xyz=" ".join(f"{v:.9g}" for v in xyz), rpy=" ".join(f"{v:.9g}" for v in rpy))
    ET.SubElement(joint, "parent", link=parent)
    ET.SubElement(joint, "child", link=name)


def build_urdf(kind: RobotKind = "panda", scope: ScopeGeometry | None = None) -> str:
    """URDF text of the arm of ``kind`` without gripper, with the laparoscope on its flange."""
    scope = scope or ScopeGeometry()
    path = arm_urdf_path(kind)
    root = _read_description(path)
    spec = arm_spec(kind)
    mount = spec.mount
    _resolve_mesh_paths(root, path)
    _strip_below(root, mount.link)
    check_description(root, path, spec)
    L = scope.length
    _add_link(root, FRAME_E, mount.link, mount.xyz, mount.rpy)
    _add_link(root, "lap_handle", FRAME_E, (0.0, 0.0, 0.0), mass=scope.handle_mass, radius=scope.handle_radius,
              length=scope.handle_length, com_z=scope.handle_offset)
    _add_link(root, "lap_shaft", FRAME_E, (0.0, 0.0, 0.0), mass=scope.shaft_mass, radius=scope.shaft_diameter / 2.0,
              length=L, com_z=L / 2.0)
    _add_link(root, FRAME_H, FRAME_E, (0.0, 0.0, scope.handle_offset))
    # the grip hangs on {H}: the F/T sensor between {H} and the scope carries its weight (not drawn: in the handle)
    _add_link(root, FRAME_GRIP, FRAME_H, (0.0, 0.0, 0.0), mass=scope.grip_mass, radius=scope.handle_radius,
              length=scope.handle_length, com=scope.grip_com, shape=False)
    _add_link(root, FRAME_TIP, FRAME_E, (0.0, 0.0, L))
    _add_link(root, FRAME_C, FRAME_E, (0.0, 0.0, L), (-math.radians(scope.oblique_angle_deg), 0.0, 0.0))
    root.set("name", f"{kind}_laparoscope")
    return ET.tostring(root, encoding="unicode")
