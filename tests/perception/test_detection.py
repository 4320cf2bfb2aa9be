"""Tracking-point rules and the detector configuration."""

from __future__ import annotations

import pytest

from lapwrench.perception import (
    Detection,
    DetectorConfig,
    TrackingPoint,
    TrackingPointRule,
)

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
def test_tracking_point_rules(rule: TrackingPointRule, expected: tuple[float, float]) -> None:
    assert rule.point(BOX, SIZE) == pytest.approx(expected)


def test_keypoint_rule_and_with_rule() -> None:
    rule = TrackingPointRule(TrackingPoint.KEYPOINT)
    assert rule.point(BOX, SIZE, keypoint=(190.0, 175.0)) == (190.0, 175.0)
    d = Detection(box=BOX, score=0.9, class_id=0, point=(150.0, 140.0), keypoint=(190.0, 175.0))
    assert d.with_rule(rule, SIZE).point == (190.0, 175.0)
    assert (d.u, d.v, d.width, d.height) == (150.0, 140.0, 100.0, 80.0)


def test_config_validation() -> None:
    with pytest.raises(ValueError, match="score_threshold"):
        DetectorConfig(score_threshold=1.5)
    with pytest.raises(ValueError, match="iou_threshold"):
        DetectorConfig(iou_threshold=0.0)
    with pytest.raises(ValueError, match="color_order"):
        DetectorConfig(color_order="hsv")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="frame_size"):
        DetectorConfig(frame_size=(0, 480))
    assert DetectorConfig(classes=[1, 2]).classes == frozenset({1, 2})  # type: ignore[arg-type]
