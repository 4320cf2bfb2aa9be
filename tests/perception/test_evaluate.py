"""mAP50 / recall / precision on hand-made boxes, and evaluate_detector on a written split."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from lapwrench.perception import Detection, DetectorConfig
from lapwrench.perception.dataset import yolo_label_lines
from lapwrench.perception.detection import Box
from lapwrench.perception.evaluate import (
    average_precision,
    evaluate_detector,
    evaluate_predictions,
    match_image,
    read_yolo_labels,
)

W, H = 640, 480

A = (100.0, 100.0, 200.0, 200.0)
B = (300.0, 300.0, 360.0, 380.0)


def det(box: Box, score: float, cls: int = 0) -> Detection:
    return Detection(box=box, score=score, class_id=cls, point=((box[0] + box[2]) / 2, (box[1] + box[3]) / 2))


def gt(*boxes: Box, cls: int = 0) -> tuple[np.ndarray, np.ndarray]:
    return (np.array(boxes, float).reshape(-1, 4), np.full(len(boxes), cls))


def test_perfect_detections() -> None:
    r = evaluate_predictions([[det(A, 0.9), det(B, 0.8)]], [gt(A, B)])
    assert r.map50 == pytest.approx(1.0) and r.recall == 1.0 and r.precision == 1.0


def test_false_positive_ranked_first_halves_precision_at_first_recall_step() -> None:
    far = (500.0, 10.0, 540.0, 50.0)
    r = evaluate_predictions([[det(far, 0.95), det(A, 0.9), det(B, 0.5)]], [gt(A, B)])
    # PR points: (0, 0), (0.5, 0.5), (1.0, 2/3); envelope: 2/3 over [0, 1].
    assert r.map50 == pytest.approx(2.0 / 3.0)
    assert r.recall == 1.0 and r.precision == pytest.approx(2.0 / 3.0)


def test_missed_box_and_operating_threshold() -> None:
    r = evaluate_predictions([[det(A, 0.9), det(B, 0.1)]], [gt(A, B)], score_threshold=0.25)
    assert r.map50 == pytest.approx(1.0)  # B is still found, at a low score
    assert r.recall == 0.5 and r.precision == 1.0


def test_low_iou_is_a_false_positive() -> None:
    shifted = (160.0, 160.0, 260.0, 260.0)  # IoU with A = 1600 / 18400
    r = evaluate_predictions([[det(shifted, 0.9)]], [gt(A)])
    assert r.map50 == 0.0 and r.recall == 0.0 and r.precision == 0.0


def test_duplicates_count_once() -> None:
    tp = match_image(np.array([A, A]), np.array([0.9, 0.8]), np.array([0, 0]), *gt(A))
    assert tp.tolist() == [True, False]


def test_classes_must_match_unless_agnostic() -> None:
    preds, truths = [[det(A, 0.9, cls=2)]], [gt(A, cls=0)]
    assert evaluate_predictions(preds, truths).map50 == 0.0
    assert evaluate_predictions(preds, truths, class_agnostic=True).map50 == pytest.approx(1.0)


def test_images_without_objects_and_array_predictions() -> None:
    preds = [(np.zeros((0, 4)), np.zeros(0), np.zeros(0, int)), (np.array([B]), np.array([0.7]), np.array([0]))]
    r = evaluate_predictions(preds, [gt(), gt(B)])
    assert r.map50 == pytest.approx(1.0) and r.n_images == 2 and r.n_ground_truth == 1


def test_average_precision_edge_cases() -> None:
    assert np.isnan(average_precision(np.array([True]), 0))
    assert average_precision(np.zeros(0, bool), 3) == 0.0


def test_length_mismatch_raises() -> None:
    with pytest.raises(ValueError, match="predictions for"):
        evaluate_predictions([[]], [gt(A), gt(B)])


class BoxDetector:
    """Reports the boxes of a given label set (knows the answers), to test the split reader."""

    def __init__(self, answers: list[list[Box]]) -> None:
        self.config = DetectorConfig(score_threshold=0.01)
        self.answers = answers
        self.calls = 0

    def detect(self, image: np.ndarray) -> list[Detection]:
        assert image.shape == (480, 640, 3)
        # The image encodes its index in pixel (0, 0), red channel (RGB order).
        i = int(image[0, 0, 0]) // 40
        self.calls += 1
        return [det(tuple(b), 0.9) for b in self.answers[i]]


def test_evaluate_detector_on_a_written_split(tmp_path: Path) -> None:
    answers = [[A], [A, B], []]
    for sub in ("images/test", "labels/test"):
        (tmp_path / sub).mkdir(parents=True)
    for i, boxes in enumerate(answers):
        img = np.zeros((480, 640, 3), np.uint8)
        img[:8, :8] = (0, 0, 40 * i)  # BGR on disk -> red channel after RGB conversion
        cv2.imwrite(str(tmp_path / "images/test" / f"{i:06d}.png"), img)
        lines = yolo_label_lines(np.array(boxes).reshape(-1, 4), np.zeros(len(boxes), int), (640, 480))
        (tmp_path / "labels/test" / f"{i:06d}.txt").write_text("\n".join(lines))
    d = BoxDetector(answers)
    r = evaluate_detector(d, tmp_path, "test")
    assert d.calls == 3 and r.n_ground_truth == 3
    assert r.map50 == pytest.approx(1.0) and r.recall == 1.0 and r.ms_per_frame is not None
    with pytest.raises(FileNotFoundError, match="no such split"):
        evaluate_detector(d, tmp_path, "val")


def test_read_labels_rejects_malformed(tmp_path: Path) -> None:
    p = tmp_path / "x.txt"
    p.write_text("0 0.5 0.5 0.1\n")
    with pytest.raises(ValueError, match="expected 'class cx cy w h'"):
        read_yolo_labels(p, (W, H))
    assert read_yolo_labels(tmp_path / "missing.txt", (W, H))[0].shape == (0, 4)
