"""The log's frames on the writer side: forward kinematics of the *logged measured* q on a
Pinocchio workspace of the writer's own (never in the loop), giving the link placements as a
tree, the scope frames E, H, C, the RCM point R and the closest point G (see the package
docstring), and the points the wrench arrows start from."""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

if TYPE_CHECKING:
    from lapwrench.robot.model import RobotModel

FRAME_R = "lap_R"
FRAME_G = "lap_G"


class Placement(NamedTuple):
    """One frame transform: ``child`` in ``parent`` (translation m, quaternion x, y, z, w)."""

    parent: str
    child: str
    translation: np.ndarray
    rotation: np.ndarray


class ScopeFrames(NamedTuple):
    """What one forward-kinematics pass gives the writer: every placement and the points the
    wrench arrows start from (all in the base frame)."""

    placements: list[Placement]
    pose_E: Placement
    anchors: dict[str, np.ndarray]


def finite_vector(x: Any) -> np.ndarray | None:
    """``x`` as a new 1-D float array if it is one with finite values only, else ``None``."""
    if x is None:
        return None
    try:
        a = np.array(x, dtype=float)
    except (TypeError, ValueError):
        return None
    return a if a.ndim == 1 and a.size and np.isfinite(a).all() else None


def finite_point(p: Any) -> np.ndarray | None:
    """A finite 3-vector as a new float array, else ``None``."""
    a = finite_vector(p)
    return a if a is not None and a.shape == (3,) else None


class FrameSolver:
    """The log's frames from the measured joints, on a Pinocchio workspace of its own (the
    controller's model data is never touched, so this may run beside the tick).

    Args:
        model: The robot model; its Pinocchio model is shared read-only.
    """

    def __init__(self, model: RobotModel) -> None:
        import pinocchio as pin

        from lapwrench.robot.description import FRAME_E, FRAME_H

        self._pin = pin
        self._model = model.model
        self._data = model.model.createData()
        frames = self._model.frames
        self._bodies = [i for i, f in enumerate(frames) if f.type == pin.FrameType.BODY]
        self.base = frames[self._bodies[0]].name
        xyzquat = pin.SE3ToXYZQUAT
        self._moving: list[tuple[int, int, str, str]] = []
        self.static: list[Placement] = []  # bodies fixed to their parent body (no joint between)
        for i in self._bodies[1:]:
            j = self._body_parent(i)
            fi, fj = frames[i], frames[j]
            if fi.parentJoint == fj.parentJoint:
                v = xyzquat(fj.placement.actInv(fi.placement))
                self.static.append(Placement(fj.name, fi.name, v[:3], v[3:]))
            else:
                self._moving.append((j, i, fj.name, fi.name))
        self._E, self._H = self._model.getFrameId(FRAME_E), self._model.getFrameId(FRAME_H)
        self._name_E = FRAME_E
        self.joint_names: list[str] = list(self._model.names)[1:]
        self.nq: int = self._model.nq

    def _body_parent(self, i: int) -> int:
        """The nearest BODY frame above frame ``i``."""
        frames = self._model.frames
        j = frames[i].parentFrame
        while frames[j].type != self._pin.FrameType.BODY and j != 0:
            j = frames[j].parentFrame
        return j

    def solve(self, q: np.ndarray, p_R: Any, p_G: Any, with_static: bool = True) -> ScopeFrames | None:
        """The placements at ``q`` (the fixed ones too if ``with_static``) plus R and G (when
        finite); ``None`` unless q is nq finite values."""
        q = np.asarray(q, dtype=float)
        if q.shape != (self._model.nq,) or not np.isfinite(q).all():
            return None
        pin, data = self._pin, self._data
        pin.forwardKinematics(self._model, data, q)
        pin.updateFramePlacements(self._model, data)
        oMf, xyzquat = data.oMf, pin.SE3ToXYZQUAT
        out = list(self.static) if with_static else []
        for parent, child, parent_name, child_name in self._moving:
            v = xyzquat(oMf[parent].actInv(oMf[child]))
            out.append(Placement(parent_name, child_name, v[:3], v[3:]))
        vE = xyzquat(oMf[self._E])
        p_E, quat_E = vE[:3], vE[3:]
        anchors = {"E": p_E, "H": oMf[self._H].translation.copy()}
        for name, frame, p in (("R", FRAME_R, p_R), ("G", FRAME_G, p_G)):
            point = finite_point(p)
            if point is not None:
                out.append(Placement(self.base, frame, point, quat_E))
                anchors[name] = point
        return ScopeFrames(out, Placement(self.base, self._name_E, p_E, quat_E), anchors)
