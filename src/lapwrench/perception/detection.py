"""Detector interface: :class:`Detection`, the :class:`Detector` protocol, frame validation.

Every backend (ONNX YOLO, ultralytics, classical OpenCV) turns one camera frame into a list of
:class:`Detection`. Each detection carries the image point ``(u, v)`` that the instrument-tracking
wrench uses (paper Sec. II-C-2, eq 9 and 11). Which point of the box that is, is an explicit,
configurable rule (:class:`TrackingPoint`): the box centre by default.

Frames are ``H x W x 3`` ``uint8`` arrays. The colour order (RGB as MuJoCo renders, or BGR as
OpenCV reads) is part of the detector configuration. Non-contiguous views are accepted.
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Literal, Protocol, runtime_checkable

import numpy as np

ColorOrder = Literal["rgb", "bgr"]
Box = tuple[float, float, float, float]
Point = tuple[float, float]


class PerceptionError(RuntimeError):
    """Base class of the perception errors."""


class FrameError(PerceptionError, ValueError):
    """A frame handed to a detector is empty, of the wrong shape, size or dtype."""


class ModelError(PerceptionError):
    """A model file is missing, corrupt, or has an output layout that cannot be decoded."""

    MAX_PROBLEM = 300
    """Longest problem text kept (a runtime's error can run over many lines)."""

    def __init__(self, path: object, problem: str) -> None:
        self.path = str(path)
        one_line = " ".join(str(problem).split())  # one line, whatever the runtime's message held
        if len(one_line) > self.MAX_PROBLEM:
            one_line = one_line[: self.MAX_PROBLEM - 3] + "..."
        self.problem = one_line
        super().__init__(f"{self.path}: {one_line}")


class BackendUnavailableError(PerceptionError, ImportError):
    """An optional backend's package is not installed."""


class TrackingPoint(enum.StrEnum):
    """Rule giving the tracking image point ``(u, v)`` of a detection.

    - ``CENTER``: the box centre (default).
    - ``EDGE_NEAREST_REFERENCE``: the midpoint of the box edge nearest the reference point (the
      image centre unless configured, e.g. the principal point ``(u0, v0)``). Instruments enter
      from the border, so this edge is usually the one holding the tip.
    - ``CLOSEST_POINT``: the point of the box closest to the reference point (the reference itself
      when it lies inside the box).
    - ``KEYPOINT``: a keypoint reported by the backend (the classical detector reports the
      instrument tip); falls back to ``CENTER`` when the backend has none.
    """

    CENTER = "center"
    EDGE_NEAREST_REFERENCE = "edge_nearest_reference"
    CLOSEST_POINT = "closest_point"
    KEYPOINT = "keypoint"


@dataclass(frozen=True)
class TrackingPointRule:
    """A :class:`TrackingPoint` mode and its reference point (``None``: the image centre)."""

    mode: TrackingPoint = TrackingPoint.CENTER
    reference: Point | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "mode", TrackingPoint(self.mode))

    def reference_for(self, image_size: tuple[int, int]) -> Point:
        """The reference point for an image of ``(width, height)`` pixels."""
        if self.reference is not None:
            return (float(self.reference[0]), float(self.reference[1]))
        width, height = image_size
        return (width / 2.0, height / 2.0)

    def point(self, box: Box, image_size: tuple[int, int], keypoint: Point | None = None) -> Point:
        """The tracking point of ``box`` (x0, y0, x1, y1) in an image of ``(width, height)``."""
        x0, y0, x1, y1 = box
        center = ((x0 + x1) / 2.0, (y0 + y1) / 2.0)
        if self.mode is TrackingPoint.CENTER:
            return center
        if self.mode is TrackingPoint.KEYPOINT:
            return (float(keypoint[0]), float(keypoint[1])) if keypoint is not None else center
        ru, rv = self.reference_for(image_size)
        if self.mode is TrackingPoint.CLOSEST_POINT:
            return (float(min(max(ru, x0), x1)), float(min(max(rv, y0), y1)))
        # EDGE_NEAREST_REFERENCE: the edge (segment) at the smallest distance from the reference.
        cu, cv = center
        edges = (
            ((x0, cv), (x0, y0), (x0, y1)),
            ((x1, cv), (x1, y0), (x1, y1)),
            ((cu, y0), (x0, y0), (x1, y0)),
            ((cu, y1), (x0, y1), (x1, y1)),
        )
        best = min(edges, key=lambda e: _segment_distance((ru, rv), e[1], e[2]))[0]
        return (float(best[0]), float(best[1]))


def _segment_distance(p: Point, a: Point, b: Point) -> float:
    """Distance from point ``p`` to the axis-aligned segment ``a``-``b``."""
    qx = min(max(p[0], min(a[0], b[0])), max(a[0], b[0]))
    qy = min(max(p[1], min(a[1], b[1])), max(a[1], b[1]))
    return float(np.hypot(p[0] - qx, p[1] - qy))


@dataclass(frozen=True)
class Detection:
    """One detected instrument.

    Attributes:
        box: ``(x0, y0, x1, y1)`` in pixels of the original frame, clipped to the frame.
        score: confidence in ``[0, 1]``.
        class_id: class index of the model.
        point: tracking image point ``(u, v)`` in pixels, from the detector's
            :class:`TrackingPointRule`.
        class_name: class name when the model provides names.
        keypoint: backend-specific keypoint (the classical detector's instrument tip), or ``None``.
    """

    box: Box
    score: float
    class_id: int
    point: Point
    class_name: str | None = None
    keypoint: Point | None = None

    @property
    def u(self) -> float:
        """Horizontal tracking coordinate (pixels)."""
        return self.point[0]

    @property
    def v(self) -> float:
        """Vertical tracking coordinate (pixels)."""
        return self.point[1]

    @property
    def center(self) -> Point:
        """Box centre (pixels)."""
        return ((self.box[0] + self.box[2]) / 2.0, (self.box[1] + self.box[3]) / 2.0)

    @property
    def width(self) -> float:
        return self.box[2] - self.box[0]

    @property
    def height(self) -> float:
        return self.box[3] - self.box[1]

    def with_rule(self, rule: TrackingPointRule, image_size: tuple[int, int]) -> Detection:
        """The same detection with its tracking point recomputed under ``rule``."""
        return replace(self, point=rule.point(self.box, image_size, self.keypoint))


@dataclass(frozen=True)
class DetectorConfig:
    """Settings shared by all backends.

    Attributes:
        score_threshold: detections scoring below this are dropped.
        iou_threshold: IoU above which NMS suppresses the lower-scoring box.
        classes: class ids to keep (``None``: all).
        agnostic_nms: NMS across classes (``True``) or within each class (``False``).
        max_detections: at most this many detections per frame, best first.
        frame_size: expected ``(width, height)`` of every frame; ``None`` accepts any size.
        color_order: channel order of the frames, ``"rgb"`` (MuJoCo) or ``"bgr"`` (OpenCV).
        tracking_point: rule giving each detection's ``(u, v)``.
    """

    score_threshold: float = 0.25
    iou_threshold: float = 0.45
    classes: frozenset[int] | None = None
    agnostic_nms: bool = False
    max_detections: int = 100
    frame_size: tuple[int, int] | None = (640, 480)
    color_order: ColorOrder = "rgb"
    tracking_point: TrackingPointRule = field(default_factory=TrackingPointRule)

    def __post_init__(self) -> None:
        if not 0.0 <= self.score_threshold <= 1.0:
            raise ValueError(f"score_threshold must lie in [0, 1], got {self.score_threshold}")
        if not 0.0 < self.iou_threshold <= 1.0:
            raise ValueError(f"iou_threshold must lie in (0, 1], got {self.iou_threshold}")
        if self.max_detections < 1:
            raise ValueError(f"max_detections must be >= 1, got {self.max_detections}")
        if self.color_order not in ("rgb", "bgr"):
            raise ValueError(f"color_order must be 'rgb' or 'bgr', got {self.color_order!r}")
        if self.classes is not None:
            object.__setattr__(self, "classes", frozenset(int(c) for c in self.classes))
        if self.frame_size is not None:
            w, h = self.frame_size
            if int(w) <= 0 or int(h) <= 0:
                raise ValueError(f"frame_size must be positive (width, height), got {self.frame_size}")
            object.__setattr__(self, "frame_size", (int(w), int(h)))


@runtime_checkable
class Detector(Protocol):
    """Anything that turns one frame into instrument detections."""

    config: DetectorConfig

    def detect(self, image: np.ndarray) -> list[Detection]:
        """Detections in ``image`` (``H x W x 3`` uint8), best score first."""
        ...


def validate_frame(image: object, frame_size: tuple[int, int] | None = None) -> np.ndarray:
    """Check that ``image`` is a usable ``H x W x 3`` uint8 frame and return it as an array.

    Args:
        image: the frame.
        frame_size: expected ``(width, height)``; ``None`` accepts any non-empty size.

    Raises:
        FrameError: not an array, empty, not 3-channel colour, wrong dtype, or wrong size.
    """
    if not isinstance(image, np.ndarray):
        raise FrameError(f"frame must be a numpy array, got {type(image).__name__}")
    if image.size == 0:
        raise FrameError(f"frame is empty (shape {image.shape})")
    if image.ndim != 3 or image.shape[2] != 3:
        raise FrameError(
            f"frame must be H x W x 3 (colour), got shape {image.shape}"
            + ("; convert grayscale with cv2.cvtColor(img, cv2.COLOR_GRAY2RGB)" if image.ndim == 2 else "")
        )
    if image.dtype != np.uint8:
        raise FrameError(
            f"frame dtype must be uint8, got {image.dtype}; scale float images with "
            "(img * 255).clip(0, 255).astype(np.uint8)"
        )
    if frame_size is not None:
        w, h = frame_size
        if image.shape[0] != h or image.shape[1] != w:
            raise FrameError(
                f"frame is {image.shape[1]}x{image.shape[0]} (WxH), expected {w}x{h} as configured"
            )
    return image


def finalize(
    boxes: np.ndarray,
    scores: np.ndarray,
    class_ids: np.ndarray,
    image_size: tuple[int, int],
    config: DetectorConfig,
    class_names: Sequence[str] | dict[int, str] | None = None,
    keypoints: Sequence[Point | None] | None = None,
) -> list[Detection]:
    """Build sorted :class:`Detection` objects from arrays in frame pixels.

    Boxes are clipped to the frame, degenerate boxes dropped, and the tracking point applied.
    """
    width, height = image_size
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4).copy()
    boxes[:, [0, 2]] = boxes[:, [0, 2]].clip(0.0, width)
    boxes[:, [1, 3]] = boxes[:, [1, 3]].clip(0.0, height)
    scores = np.asarray(scores, dtype=np.float64).reshape(-1)
    class_ids = np.asarray(class_ids).reshape(-1).astype(np.int64)
    order = np.argsort(-scores, kind="stable")
    out: list[Detection] = []
    for i in order:
        x0, y0, x1, y1 = (float(c) for c in boxes[i])
        if x1 <= x0 or y1 <= y0:
            continue
        cid = int(class_ids[i])
        name: str | None = None
        if class_names is not None:
            if isinstance(class_names, dict):
                name = class_names.get(cid)
            elif 0 <= cid < len(class_names):
                name = class_names[cid]
        kp = keypoints[i] if keypoints is not None else None
        box = (x0, y0, x1, y1)
        out.append(
            Detection(
                box=box,
                score=float(scores[i]),
                class_id=cid,
                point=config.tracking_point.point(box, image_size, kp),
                class_name=name,
                keypoint=kp,
            )
        )
        if len(out) >= config.max_detections:
            break
    return out
