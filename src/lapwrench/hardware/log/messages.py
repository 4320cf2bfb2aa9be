"""Foxglove's standard messages (``foxglove.messages``) the writer thread builds: frame
transforms, the scope pose, joint states, the wrench arrows, camera images and log levels."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from lapwrench.hardware.log.frames import Placement
from lapwrench.hardware.log.record import plain_float

if TYPE_CHECKING:
    from foxglove.messages import CompressedImage, FrameTransforms, JointStates, PoseInFrame, SceneUpdate, Timestamp

ARROW_M_PER_N = 0.01  # wrench arrows: 1 cm per N
JPEG_QUALITY = 85
IMAGE_FRAME = "lap_C"

_WRENCH_ANCHOR = {"rcm": "R", "interaction": "H"}  # the others at G (E without G)
_WRENCH_COLOR = {"rcm": (0.9, 0.2, 0.2), "interaction": (0.2, 0.5, 0.95), "tracking": (0.2, 0.8, 0.3)}


def stamp(ns: int) -> Timestamp:
    """A log time in ns as a ``foxglove.Timestamp``."""
    from foxglove.messages import Timestamp

    return Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def _vector3(p: Any) -> Any:
    from foxglove.messages import Vector3

    x, y, z = p.tolist() if isinstance(p, np.ndarray) else p
    return Vector3(x=x, y=y, z=z)


def _quaternion(q: Any) -> Any:
    from foxglove.messages import Quaternion

    x, y, z, w = q.tolist() if isinstance(q, np.ndarray) else q
    return Quaternion(x=x, y=y, z=z, w=w)


def _pose(p: Any, quat: Any) -> Any:
    from foxglove.messages import Pose

    return Pose(position=_vector3(p), orientation=_quaternion(quat))


def frame_transforms_message(ns: int, placements: list[Placement]) -> FrameTransforms:
    """``foxglove.FrameTransforms`` of the placements, stamped ``ns``."""
    from foxglove.messages import FrameTransform, FrameTransforms

    ts = stamp(ns)
    return FrameTransforms(
        transforms=[
            FrameTransform(
                timestamp=ts,
                parent_frame_id=p.parent,
                child_frame_id=p.child,
                translation=_vector3(p.translation),
                rotation=_quaternion(p.rotation),
            )
            for p in placements
        ]
    )


def pose_message(ns: int, pose: Placement) -> PoseInFrame:
    """``foxglove.PoseInFrame`` of ``pose.child`` in ``pose.parent``."""
    from foxglove.messages import PoseInFrame

    return PoseInFrame(timestamp=stamp(ns), frame_id=pose.parent, pose=_pose(pose.translation, pose.rotation))


def joint_states_message(ns: int, names: list[str], q: Any, dq: Any, tau: Any) -> JointStates:
    """``foxglove.JointStates`` of the measured joints (missing or non-finite values left out)."""
    from foxglove.messages import JointState, JointStates

    def value(x: Any, j: int) -> float | None:
        if x is None or j >= len(x):
            return None
        return plain_float(x[j])

    joints = [
        JointState(name=n, position=value(q, j), velocity=value(dq, j), effort=value(tau, j))
        for j, n in enumerate(names)
    ]
    return JointStates(timestamp=stamp(ns), joints=joints)


def _x_to(x: float, y: float, z: float) -> list[float]:
    """Quaternion (x, y, z, w) turning +x onto the unit vector (x, y, z) (arrows point along +x)."""
    if x < -1.0 + 1e-9:
        return [0.0, 0.0, 1.0, 0.0]
    n = math.sqrt(z * z + y * y + (1.0 + x) ** 2)
    return [0.0, -z / n, y / n, (1.0 + x) / n]


def _arrow(p: np.ndarray, force: list[float], rgb: tuple[float, float, float]) -> Any:
    """An arrow from ``p`` along ``force``, ``ARROW_M_PER_N`` m per N; ``None`` for a null force."""
    from foxglove.messages import ArrowPrimitive, Color

    fx, fy, fz = force
    norm = math.sqrt(fx * fx + fy * fy + fz * fz)
    if not math.isfinite(norm) or norm < 1e-6:
        return None
    length = ARROW_M_PER_N * norm
    head = min(0.3 * length, 0.01)
    return ArrowPrimitive(
        pose=_pose(p, _x_to(fx / norm, fy / norm, fz / norm)),
        shaft_length=length - head,
        shaft_diameter=0.003,
        head_length=head,
        head_diameter=0.008,
        color=Color(r=rgb[0], g=rgb[1], b=rgb[2], a=1.0),
    )


def wrench_scene_message(ns: int, base: str, wrenches: dict[str, Any], anchors: dict[str, np.ndarray]) -> SceneUpdate:
    """``foxglove.SceneUpdate``: one entity per wrench with an arrow along its force at its point."""
    from foxglove.messages import SceneEntity, SceneUpdate

    ts = stamp(ns)
    entities = []
    for name, w in wrenches.items():
        point = anchors.get(_WRENCH_ANCHOR.get(name, "G"), anchors["E"])
        color = _WRENCH_COLOR.get(name, (0.8, 0.6, 0.1))
        arrow = None if w is None else _arrow(point, np.asarray(w, dtype=float)[3:6].tolist(), color)
        entities.append(SceneEntity(timestamp=ts, frame_id=base, id=str(name), arrows=[] if arrow is None else [arrow]))
    return SceneUpdate(entities=entities)


def image_message(ns: int, frame: Any, fmt: str) -> CompressedImage:
    """``foxglove.CompressedImage`` in ``lap_C``: bytes as they are (``fmt``), arrays as JPEG."""
    from foxglove.messages import CompressedImage

    if isinstance(frame, bytes | bytearray | memoryview):
        return CompressedImage(timestamp=stamp(ns), frame_id=IMAGE_FRAME, data=bytes(frame), format=fmt)
    return CompressedImage(timestamp=stamp(ns), frame_id=IMAGE_FRAME, data=encode_jpeg(frame), format="jpeg")


def encode_jpeg(frame: Any) -> bytes:
    """JPEG bytes of an RGB (H×W×3) or grey (H×W) uint8 image (OpenCV releases the GIL here)."""
    import cv2

    a = np.asarray(frame)
    if a.dtype != np.uint8:
        a = np.clip(a, 0, 255).astype(np.uint8)
    if a.ndim == 3 and a.shape[2] == 3:
        a = cv2.cvtColor(a, cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".jpg", a, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise ValueError(f"cannot JPEG-encode an image of shape {a.shape}")
    return buf.tobytes()


def log_level(kind: str) -> Any:
    """The ``foxglove.Log`` level of an event kind: ERROR for errors, INFO for start, stop and
    input_fresh, WARNING for the rest."""
    from foxglove.messages import LogLevel

    if "error" in kind:
        return LogLevel.Error
    if kind in ("start", "stop", "input_fresh"):
        return LogLevel.Info
    return LogLevel.Warning
