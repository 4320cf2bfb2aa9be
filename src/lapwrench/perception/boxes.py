"""Letterboxing, un-letterboxing and non-maximum suppression for YOLO-style detectors."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

PAD_VALUE = 114
"""Gray level YOLO uses to pad letterboxed images."""


@dataclass(frozen=True)
class Letterbox:
    """How a frame was mapped into the network input.

    ``input = frame * ratio + (pad_x, pad_y)``; :meth:`unmap_boxes` inverts it.
    """

    ratio: float
    pad_x: int
    pad_y: int
    input_size: tuple[int, int]
    """Network input ``(height, width)``."""

    def unmap_boxes(self, boxes: np.ndarray) -> np.ndarray:
        """Boxes ``(N, 4)`` xyxy in network-input pixels -> frame pixels (not clipped)."""
        out = np.asarray(boxes, dtype=np.float64).reshape(-1, 4).copy()
        out[:, [0, 2]] -= self.pad_x
        out[:, [1, 3]] -= self.pad_y
        out /= self.ratio
        return out

    def map_boxes(self, boxes: np.ndarray) -> np.ndarray:
        """Boxes ``(N, 4)`` xyxy in frame pixels -> network-input pixels."""
        out = np.asarray(boxes, dtype=np.float64).reshape(-1, 4) * self.ratio
        out[:, [0, 2]] += self.pad_x
        out[:, [1, 3]] += self.pad_y
        return out


def letterbox_size(
    frame_hw: tuple[int, int], target_hw: tuple[int, int], *, auto: bool, stride: int = 32, scaleup: bool = True
) -> tuple[float, tuple[int, int], tuple[int, int]]:
    """Resize ratio, resized ``(h, w)`` and padded input ``(h, w)`` for a frame.

    With ``auto`` the padding is only what aligns each side to ``stride`` (dynamic-shape models),
    so a 640x480 frame with target 640 gives a 640x480 input, not 640x640.
    """
    h, w = frame_hw
    th, tw = target_hw
    ratio = min(th / h, tw / w)
    if not scaleup:
        ratio = min(ratio, 1.0)
    new_h, new_w = round(h * ratio), round(w * ratio)
    if auto:
        in_h = int(np.ceil(new_h / stride) * stride)
        in_w = int(np.ceil(new_w / stride) * stride)
    else:
        in_h, in_w = th, tw
    return ratio, (new_h, new_w), (in_h, in_w)


def letterbox(
    image: np.ndarray,
    target_hw: tuple[int, int],
    *,
    auto: bool = False,
    stride: int = 32,
    scaleup: bool = True,
    pad_value: int = PAD_VALUE,
) -> tuple[np.ndarray, Letterbox]:
    """Resize keeping the aspect ratio and pad with gray to the network input size.

    Args:
        image: ``H x W x C`` frame.
        target_hw: network input ``(height, width)`` (the maximum size when ``auto``).
        auto: pad only to a multiple of ``stride`` (for models with dynamic input axes).
        stride: the model's maximum stride.
        scaleup: allow enlarging frames smaller than the target.
        pad_value: padding gray level (YOLO uses 114).

    Returns:
        The padded image and the :class:`Letterbox` to map boxes back.
    """
    h, w = image.shape[:2]
    ratio, (new_h, new_w), (in_h, in_w) = letterbox_size((h, w), target_hw, auto=auto, stride=stride,
                                                         scaleup=scaleup)
    if (new_h, new_w) != (h, w):
        image = cv2.resize(image, (new_w, new_h), interpolation=cv2.INTER_LINEAR)
    dh, dw = (in_h - new_h) / 2.0, (in_w - new_w) / 2.0
    top, bottom = round(dh - 0.1), round(dh + 0.1)
    left, right = round(dw - 0.1), round(dw + 0.1)
    # Rounding may leave the total one pixel off the target; fix it on the bottom/right side.
    bottom += in_h - (new_h + top + bottom)
    right += in_w - (new_w + left + right)
    if top or bottom or left or right:
        image = cv2.copyMakeBorder(image, top, bottom, left, right, cv2.BORDER_CONSTANT,
                                   value=(pad_value,) * 3)
    return image, Letterbox(ratio=ratio, pad_x=left, pad_y=top, input_size=(in_h, in_w))


def xywh_to_xyxy(xywh: np.ndarray) -> np.ndarray:
    """Centre-size boxes ``(N, 4)`` -> corner boxes ``(N, 4)``."""
    xywh = np.asarray(xywh, dtype=np.float32)
    out = np.empty_like(xywh)
    half_w, half_h = xywh[:, 2] / 2.0, xywh[:, 3] / 2.0
    out[:, 0] = xywh[:, 0] - half_w
    out[:, 1] = xywh[:, 1] - half_h
    out[:, 2] = xywh[:, 0] + half_w
    out[:, 3] = xywh[:, 1] + half_h
    return out


def box_iou(box: np.ndarray, boxes: np.ndarray) -> np.ndarray:
    """IoU of one xyxy box against ``(N, 4)`` xyxy boxes."""
    ix0 = np.maximum(box[0], boxes[:, 0])
    iy0 = np.maximum(box[1], boxes[:, 1])
    ix1 = np.minimum(box[2], boxes[:, 2])
    iy1 = np.minimum(box[3], boxes[:, 3])
    inter = np.clip(ix1 - ix0, 0, None) * np.clip(iy1 - iy0, 0, None)
    area = (box[2] - box[0]) * (box[3] - box[1])
    areas = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    union = area + areas - inter
    return np.where(union > 0, inter / np.maximum(union, 1e-12), 0.0)


def mirror_boxes(boxes: np.ndarray, width: float) -> np.ndarray:
    """xyxy boxes found in a horizontally mirrored image of ``width`` pixels, in the original image."""
    out = np.array(boxes, dtype=np.float64).reshape(-1, 4)
    out[:, [0, 2]] = width - out[:, [2, 0]]
    return out


def fuse_boxes(
    boxes: np.ndarray,
    scores: np.ndarray,
    keep: np.ndarray,
    iou_threshold: float,
    class_ids: np.ndarray | None = None,
) -> np.ndarray:
    """Each kept box replaced by the score-weighted mean of the boxes overlapping it.

    The merge step of test-time augmentation: after NMS over the candidates of several passes,
    every kept box absorbs the boxes it suppressed (IoU above ``iou_threshold``, itself included,
    of its own class when ``class_ids`` is given), so both passes shape the final box instead of
    the best-scoring one alone.

    Returns:
        ``(len(keep), 4)`` xyxy boxes, in the order of ``keep``.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    scores = np.asarray(scores, dtype=np.float64).reshape(-1)
    classes = None if class_ids is None else np.asarray(class_ids).reshape(-1)
    fused = np.empty((len(keep), 4))
    for row, i in enumerate(keep):
        near = box_iou(boxes[i], boxes) > iou_threshold
        if classes is not None:
            near &= classes == classes[i]
        near[i] = True
        w = scores[near]
        fused[row] = (boxes[near] * w[:, None]).sum(axis=0) / w.sum()
    return fused


def nms(
    boxes: np.ndarray,
    scores: np.ndarray,
    iou_threshold: float,
    class_ids: np.ndarray | None = None,
    max_keep: int | None = None,
) -> np.ndarray:
    """Greedy non-maximum suppression, vectorised per kept box.

    Args:
        boxes: ``(N, 4)`` xyxy.
        scores: ``(N,)``.
        iou_threshold: a box overlapping a better kept box with IoU above this is suppressed.
        class_ids: when given, suppression only acts within each class (boxes are offset per
            class so that different classes never overlap).
        max_keep: stop after this many kept boxes.

    Returns:
        Indices of the kept boxes, best score first.
    """
    boxes = np.asarray(boxes, dtype=np.float64).reshape(-1, 4)
    scores = np.asarray(scores, dtype=np.float64).reshape(-1)
    if boxes.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    # per class: a box only competes with boxes of its own class (a mask, not offsetting the boxes per
    # class, which loses every box to rounding once one box or class id is huge)
    classes = None if class_ids is None else np.asarray(class_ids).reshape(-1)
    order = np.argsort(-scores, kind="stable")
    keep: list[int] = []
    while order.size:
        i = int(order[0])
        keep.append(i)
        if max_keep is not None and len(keep) >= max_keep:
            break
        rest = order[1:]
        if rest.size == 0:
            break
        survive = ~(box_iou(boxes[i], boxes[rest]) > iou_threshold)  # only a definite overlap suppresses
        if classes is not None:
            survive |= classes[rest] != classes[i]
        order = rest[survive]
    return np.asarray(keep, dtype=np.int64)
