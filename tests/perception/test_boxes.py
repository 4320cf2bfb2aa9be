"""Letterboxing, NMS, box mirroring and fusion."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.perception import (
    letterbox,
    nms,
)
from lapwrench.perception.boxes import PAD_VALUE, box_iou, fuse_boxes, mirror_boxes


@pytest.mark.parametrize(
    ("frame_hw", "target", "auto", "expected_hw", "pad"),
    [
        ((480, 640), (640, 640), False, (640, 640), (0, 80)),
        ((480, 640), (320, 320), False, (320, 320), (0, 40)),
        ((480, 640), (640, 640), True, (480, 640), (0, 0)),
        ((480, 640), (320, 320), True, (256, 320), (0, 8)),
        ((500, 300), (640, 640), True, (640, 384), (0, 0)),  # 384 = ceil(384/32)*32, no bars
        ((481, 641), (640, 640), False, (640, 640), (0, 80)),
    ],
)
def test_letterbox_geometry(
    frame_hw: tuple[int, int], target: tuple[int, int], auto: bool, expected_hw: tuple[int, int], pad: tuple[int, int]
) -> None:
    img = np.full((*frame_hw, 3), 200, np.uint8)
    out, lb = letterbox(img, target, auto=auto)
    assert out.shape == (*expected_hw, 3)
    assert lb.input_size == expected_hw
    assert (lb.pad_x, lb.pad_y) == pad
    if pad[1]:
        assert (out[: pad[1] - 1] == PAD_VALUE).all()  # gray bars
        assert (out[pad[1] + 2 : expected_hw[0] - pad[1] - 2] == 200).all()


def test_letterbox_roundtrip() -> None:
    img = np.zeros((480, 640, 3), np.uint8)
    _, lb = letterbox(img, (416, 416))
    boxes = np.array([[0, 0, 640, 480], [100.5, 20.25, 300, 470]])
    np.testing.assert_allclose(lb.unmap_boxes(lb.map_boxes(boxes)), boxes, atol=1e-9)
    # The whole frame maps onto the unpadded region of the input.
    x0, y0, x1, y1 = lb.map_boxes(boxes[:1])[0]
    assert (x0, x1) == pytest.approx((0, 416)) and (y0, y1) == pytest.approx((52, 364))


def test_nms_matches_brute_force() -> None:
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 200, (150, 2))
    wh = rng.uniform(10, 60, (150, 2))
    boxes = np.c_[xy, xy + wh]
    scores = rng.uniform(0, 1, 150)
    keep = nms(boxes, scores, 0.5)
    # Brute force: walk in score order, keep a box unless it overlaps a kept one above 0.5.
    ref: list[int] = []
    for i in np.argsort(-scores):
        if all(box_iou(boxes[i], boxes[[j]])[0] <= 0.5 for j in ref):
            ref.append(int(i))
    assert keep.tolist() == ref


def test_mirror_boxes_is_an_involution() -> None:
    boxes = np.array([[10.0, 5.0, 50.0, 25.0], [0.0, 0.0, 320.0, 10.0]])
    np.testing.assert_allclose(mirror_boxes(boxes, 320), [[270.0, 5.0, 310.0, 25.0], [0.0, 0.0, 320.0, 10.0]])
    np.testing.assert_allclose(mirror_boxes(mirror_boxes(boxes, 320), 320), boxes)


def test_fuse_boxes_weights_overlapping_boxes_by_score() -> None:
    boxes = np.array([[0.0, 0.0, 10.0, 10.0], [1.0, 0.0, 11.0, 10.0], [50.0, 50.0, 60.0, 60.0], [0.0, 0.0, 10.0, 9.0]])
    scores = np.array([0.6, 0.3, 0.9, 0.5])
    fused = fuse_boxes(boxes, scores, np.array([2, 0]), 0.55)
    np.testing.assert_allclose(fused[0], boxes[2])  # nothing overlaps the far box
    expected = (0.6 * boxes[0] + 0.3 * boxes[1] + 0.5 * boxes[3]) / 1.4
    np.testing.assert_allclose(fused[1], expected)
    # with classes, only boxes of the kept box's class are absorbed
    fused = fuse_boxes(boxes, scores, np.array([0]), 0.55, class_ids=np.array([0, 0, 0, 1]))
    np.testing.assert_allclose(fused[0], (0.6 * boxes[0] + 0.3 * boxes[1]) / 0.9)


def test_nms_per_class_and_max_keep() -> None:
    boxes = np.array([[0, 0, 10, 10], [1, 1, 11, 11], [0, 0, 10, 10]], float)
    scores = np.array([0.9, 0.8, 0.7])
    assert nms(boxes, scores, 0.5).tolist() == [0]
    assert nms(boxes, scores, 0.5, class_ids=np.array([0, 0, 1])).tolist() == [0, 2]
    assert nms(boxes, scores, 0.99, max_keep=2).tolist() == [0, 1]
    assert nms(np.zeros((0, 4)), np.zeros(0), 0.5).tolist() == []
