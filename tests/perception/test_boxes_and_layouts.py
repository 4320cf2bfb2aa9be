"""Letterboxing, NMS, tracking-point rules and the pure layout inference."""

from __future__ import annotations

import numpy as np
import pytest

from lapwrench.perception import (
    Detection,
    DetectorConfig,
    OutputLayout,
    TrackingPoint,
    TrackingPointRule,
    infer_layout,
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
def test_letterbox_geometry(frame_hw, target, auto, expected_hw, pad):
    img = np.full((*frame_hw, 3), 200, np.uint8)
    out, lb = letterbox(img, target, auto=auto)
    assert out.shape == (*expected_hw, 3)
    assert lb.input_size == expected_hw
    assert (lb.pad_x, lb.pad_y) == pad
    if pad[1]:
        assert (out[: pad[1] - 1] == PAD_VALUE).all()  # gray bars
        assert (out[pad[1] + 2 : expected_hw[0] - pad[1] - 2] == 200).all()


def test_letterbox_roundtrip():
    img = np.zeros((480, 640, 3), np.uint8)
    _, lb = letterbox(img, (416, 416))
    boxes = np.array([[0, 0, 640, 480], [100.5, 20.25, 300, 470]])
    np.testing.assert_allclose(lb.unmap_boxes(lb.map_boxes(boxes)), boxes, atol=1e-9)
    # The whole frame maps onto the unpadded region of the input.
    x0, y0, x1, y1 = lb.map_boxes(boxes[:1])[0]
    assert (x0, x1) == pytest.approx((0, 416)) and (y0, y1) == pytest.approx((52, 364))


def test_nms_matches_brute_force():
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


def test_mirror_boxes_is_an_involution():
    boxes = np.array([[10.0, 5.0, 50.0, 25.0], [0.0, 0.0, 320.0, 10.0]])
    np.testing.assert_allclose(mirror_boxes(boxes, 320), [[270.0, 5.0, 310.0, 25.0], [0.0, 0.0, 320.0, 10.0]])
    np.testing.assert_allclose(mirror_boxes(mirror_boxes(boxes, 320), 320), boxes)


def test_fuse_boxes_weights_overlapping_boxes_by_score():
    boxes = np.array([[0.0, 0.0, 10.0, 10.0], [1.0, 0.0, 11.0, 10.0], [50.0, 50.0, 60.0, 60.0], [0.0, 0.0, 10.0, 9.0]])
    scores = np.array([0.6, 0.3, 0.9, 0.5])
    fused = fuse_boxes(boxes, scores, np.array([2, 0]), 0.55)
    np.testing.assert_allclose(fused[0], boxes[2])  # nothing overlaps the far box
    expected = (0.6 * boxes[0] + 0.3 * boxes[1] + 0.5 * boxes[3]) / 1.4
    np.testing.assert_allclose(fused[1], expected)
    # with classes, only boxes of the kept box's class are absorbed
    fused = fuse_boxes(boxes, scores, np.array([0]), 0.55, class_ids=np.array([0, 0, 0, 1]))
    np.testing.assert_allclose(fused[0], (0.6 * boxes[0] + 0.3 * boxes[1]) / 0.9)


def test_nms_per_class_and_max_keep():
    boxes = np.array([[0, 0, 10, 10], [1, 1, 11, 11], [0, 0, 10, 10]], float)
    scores = np.array([0.9, 0.8, 0.7])
    assert nms(boxes, scores, 0.5).tolist() == [0]
    assert nms(boxes, scores, 0.5, class_ids=np.array([0, 0, 1])).tolist() == [0, 2]
    assert nms(boxes, scores, 0.99, max_keep=2).tolist() == [0, 1]
    assert nms(np.zeros((0, 4)), np.zeros(0), 0.5).tolist() == []


BOX = (100.0, 100.0, 200.0, 180.0)
SIZE = (640, 480)


@pytest.mark.parametrize(
    ("rule", "expected"),
    [
        (TrackingPointRule(), (150.0, 140.0)),
        (TrackingPointRule(TrackingPoint.EDGE_NEAREST_REFERENCE), (200.0, 140.0)),
        (TrackingPointRule(TrackingPoint.EDGE_NEAREST_REFERENCE, reference=(150.0, 400.0)), (150.0, 180.0)),
        (TrackingPointRule(TrackingPoint.CLOSEST_POINT), (200.0, 180.0)),
        (TrackingPointRule(TrackingPoint.CLOSEST_POINT, reference=(120.0, 130.0)), (120.0, 130.0)),
        (TrackingPointRule("keypoint"), (150.0, 140.0)),  # no keypoint: centre
    ],
)
def test_tracking_point_rules(rule, expected):
    assert rule.point(BOX, SIZE) == pytest.approx(expected)


def test_keypoint_rule_and_with_rule():
    rule = TrackingPointRule(TrackingPoint.KEYPOINT)
    assert rule.point(BOX, SIZE, keypoint=(190.0, 175.0)) == (190.0, 175.0)
    d = Detection(box=BOX, score=0.9, class_id=0, point=(150.0, 140.0), keypoint=(190.0, 175.0))
    assert d.with_rule(rule, SIZE).point == (190.0, 175.0)
    assert (d.u, d.v, d.width, d.height) == (150.0, 140.0, 100.0, 80.0)


def test_config_validation():
    with pytest.raises(ValueError, match="score_threshold"):
        DetectorConfig(score_threshold=1.5)
    with pytest.raises(ValueError, match="iou_threshold"):
        DetectorConfig(iou_threshold=0.0)
    with pytest.raises(ValueError, match="color_order"):
        DetectorConfig(color_order="hsv")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="frame_size"):
        DetectorConfig(frame_size=(0, 480))
    assert DetectorConfig(classes=[1, 2]).classes == frozenset({1, 2})  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("outputs", "kwargs", "layout", "nc"),
    [
        ([("output0", (1, 84, 8400))], {}, OutputLayout.YOLOV8, 80),
        ([("output0", (1, 5, 6300))], {}, OutputLayout.YOLOV8, 1),
        ([("output", (1, 25200, 85))], {}, OutputLayout.YOLOV5, 80),
        ([("output", (1, 25200, 6))], {}, OutputLayout.YOLOV5, 1),
        # YOLOv7 raw export with the three per-level grids as extra outputs.
        ([("output", (1, 25200, 7)), ("g1", (1, 3, 80, 80, 7)), ("g2", (1, 3, 40, 40, 7))], {},
         OutputLayout.YOLOV5, 2),
        ([("output", (12, 7))], {}, OutputLayout.YOLOV7_E2E, None),
        ([("output", (0, 7))], {}, OutputLayout.YOLOV7_E2E, None),
        ([("num_dets", (1, 1)), ("det_boxes", (1, 100, 4)), ("det_scores", (1, 100)),
          ("det_classes", (1, 100))], {}, OutputLayout.YOLOV7_E2E_SPLIT, None),
        # Same by shape only, unnamed outputs.
        ([("a", (1, 1)), ("b", (1, 100, 4)), ("c", (1, 100)), ("d", (1, 100))], {},
         OutputLayout.YOLOV7_E2E_SPLIT, None),
        # Tiny ambiguous shapes settled by num_classes.
        ([("o", (1, 6, 6))], {"num_classes": 2}, OutputLayout.YOLOV8, 2),
        ([("o", (1, 7, 6))], {"num_classes": 1}, OutputLayout.YOLOV5, 1),
        ([("output0", (1, 300, 6))], {"end2end": True}, OutputLayout.E2E_XYXY_SCORE_CLS, None),
    ],
)
def test_infer_layout(outputs, kwargs, layout, nc):
    info = infer_layout(outputs, **kwargs)
    assert info.layout is layout
    assert info.num_classes == nc


def test_infer_layout_split_output_order():
    outs = [("det_classes", (1, 50)), ("det_scores", (1, 50)), ("det_boxes", (1, 50, 4)), ("num_dets", (1, 1))]
    assert infer_layout(outs).outputs == (3, 2, 1, 0)


@pytest.mark.parametrize(
    ("outputs", "kwargs"),
    [
        ([("o", (1, 6, 6))], {}),
        ([("o", (1, 84, 8400))], {"num_classes": 3}),
        ([("o", (2, 84, 8400))], {}),
        ([("o", (10, 6))], {}),
        ([("o", (1, 100, 7))], {"end2end": True}),
    ],
)
def test_infer_layout_rejects(outputs, kwargs):
    with pytest.raises(ValueError):
        infer_layout(outputs, **kwargs)
