"""Classical OpenCV detector on synthetic drawn scenes (pink tissue, dark shafts, light jaws)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from lapwrench.perception import (
    ClassicalDetector,
    Detection,
    DetectorConfig,
    FrameError,
    TrackingPoint,
    TrackingPointRule,
    make_detector,
)
from lapwrench.perception.boxes import box_iou
from lapwrench.perception.synthetic import (
    DrawnInstrument,
    draw_instrument,
    draw_instrument_scene,
    draw_speckles,
    tissue_background,
)


def match(dets: list[Detection], truth: list[DrawnInstrument], iou: float = 0.5) -> tuple[int, int, int, list[float]]:
    """(true positives, false positives, false negatives, tip errors in px) by greedy IoU matching."""
    used: set[int] = set()
    tips = []
    for g in truth:
        ious = [(box_iou(np.array(g.box), np.array([d.box]))[0], i) for i, d in enumerate(dets) if i not in used]
        best = max(ious, default=(0.0, -1))
        if best[0] >= iou:
            used.add(best[1])
            kp = dets[best[1]].keypoint
            tips.append(float(np.hypot(kp[0] - g.tip[0], kp[1] - g.tip[1])))
    tp = len(used)
    return tp, len(dets) - tp, len(truth) - tp, tips


def test_finds_drawn_instruments_and_their_tips() -> None:
    det = ClassicalDetector()
    tp = fp = fn = 0
    tips: list[float] = []
    for seed in range(24):
        img, truth = draw_instrument_scene(n_instruments=1 + seed % 3, seed=seed,
                                           blur=1.0 if seed % 3 == 0 else 0.0, noise=6.0 if seed % 2 else 0.0)
        a, b, c, t = match(det.detect(img), truth)
        tp, fp, fn = tp + a, fp + b, fn + c
        tips += t
    precision, recall = tp / (tp + fp), tp / (tp + fn)
    assert precision >= 0.9, (tp, fp, fn)
    assert recall >= 0.9, (tp, fp, fn)
    assert np.median(tips) < 5.0
    assert np.percentile(tips, 90) < 10.0


def test_single_instrument_exact() -> None:
    rng = np.random.default_rng(5)
    img = tissue_background((640, 480), rng)
    g = draw_instrument(img, (-20, 100), (330, 250), rng, width=16)
    rule = TrackingPointRule(TrackingPoint.KEYPOINT)
    (d,) = ClassicalDetector(DetectorConfig(tracking_point=rule)).detect(img)
    assert box_iou(np.array(g.box), np.array([d.box]))[0] > 0.9
    assert d.point == d.keypoint
    assert np.hypot(d.u - g.tip[0], d.v - g.tip[1]) < 4.0
    assert d.class_name == "instrument" and 0.0 < d.score <= 1.0


def test_ignores_speckles_and_vessels() -> None:
    det = ClassicalDetector()
    for seed in range(10):
        rng = np.random.default_rng(100 + seed)
        img = tissue_background((640, 480), rng)
        draw_speckles(img, rng, n_bright=150, n_dark=60)
        assert det.detect(img) == [], f"seed {seed}"


def test_bright_speckle_on_its_own_is_not_a_jaw() -> None:
    rng = np.random.default_rng(9)
    img = tissue_background((640, 480), rng)
    for x in range(60, 600, 40):  # a row of large specular highlights
        cv2.circle(img, (x, 400), 6, (250, 250, 250), -1)
    assert ClassicalDetector().detect(img) == []


def test_crossing_instruments_are_split() -> None:
    rng = np.random.default_rng(2)
    img = tissue_background((640, 480), rng)
    g1 = draw_instrument(img, (-20, 60), (420, 330), rng, width=16)
    g2 = draw_instrument(img, (-20, 400), (400, 120), rng, width=16)
    tp, fp, fn, tips = match(ClassicalDetector().detect(img), [g1, g2])
    assert (tp, fp, fn) == (2, 0, 0)
    assert max(tips) < 6.0


def test_bgr_input_and_class_filter() -> None:
    img, _ = draw_instrument_scene(n_instruments=1, seed=3)
    bgr = np.ascontiguousarray(img[..., ::-1])
    assert len(ClassicalDetector(DetectorConfig(color_order="bgr")).detect(bgr)) == 1
    assert ClassicalDetector(DetectorConfig(classes=frozenset({1}))).detect(img) == []
    assert isinstance(make_detector("classical"), ClassicalDetector)


@pytest.mark.parametrize(
    "image",
    [np.zeros((0, 640, 3), np.uint8), np.zeros((480, 640), np.uint8), np.zeros((480, 640, 3), np.float64),
     np.zeros((480, 320, 3), np.uint8)],
    ids=["empty", "gray", "float", "wrong-size"],
)
def test_bad_frames(image: np.ndarray) -> None:
    with pytest.raises(FrameError):
        ClassicalDetector().detect(image)
