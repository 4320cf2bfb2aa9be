"""Detection accuracy of any :class:`Detector` on a YOLO-format split: mAP50, recall, precision.

Every backend (ONNX, ultralytics, classical) is measured the same way:

- ground truth: the split's label files (``class cx cy w h``, normalised) as pixel boxes;
- a detection matches the unmatched ground-truth box of the same class with the highest IoU if
  that IoU is >= ``iou_threshold`` (0.5), detections taken best score first (greedy, per image);
- **AP50** per class: area under the precision-recall curve over all detections sorted by score,
  with the precision envelope made monotone and integrated at every recall step (all-point
  interpolation, as VOC2010+/COCO without the 101-point sampling); **mAP50** is its mean over
  the classes that have ground truth;
- **recall** and **precision** at the operating threshold ``score_threshold`` (the detections a
  controller would use), from the same matching.

The detector's own ``config.score_threshold`` limits what it returns; for a faithful AP give it a
low threshold (e.g. 0.01) and set the operating threshold here.
"""

from __future__ import annotations

import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from lapwrench.perception.boxes import box_iou
from lapwrench.perception.detection import Detection, Detector

IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp")


@dataclass(frozen=True)
class GroundTruth:
    """Boxes (xyxy pixels) and class ids of one image."""

    image: Path
    boxes: np.ndarray
    classes: np.ndarray


@dataclass(frozen=True)
class EvalResult:
    map50: float
    recall: float
    precision: float
    ap50_per_class: dict[int, float]
    n_images: int
    n_ground_truth: int
    n_detections: int
    score_threshold: float
    ms_per_frame: float | None = None


def read_yolo_labels(path: str | os.PathLike[str], image_size: tuple[int, int]) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (xyxy pixels) and classes from a YOLO label file for an image of ``(w, h)``.

    A missing file means no objects. Raises ``ValueError`` on a malformed line.
    """
    p = Path(path)
    w, h = image_size
    if not p.is_file():
        return np.zeros((0, 4)), np.zeros(0, np.int64)
    boxes, classes = [], []
    for n, line in enumerate(p.read_text().splitlines(), 1):
        parts = line.split()
        if not parts:
            continue
        if len(parts) != 5:
            raise ValueError(f"{p}:{n}: expected 'class cx cy w h', got {line!r}")
        c, cx, cy, bw, bh = int(parts[0]), *(float(x) for x in parts[1:])
        boxes.append(((cx - bw / 2) * w, (cy - bh / 2) * h, (cx + bw / 2) * w, (cy + bh / 2) * h))
        classes.append(c)
    return np.asarray(boxes, np.float64).reshape(-1, 4), np.asarray(classes, np.int64)


def read_yolo_split(root: str | os.PathLike[str], split: str,
                    image_size: tuple[int, int] | None = None) -> list[GroundTruth]:
    """Ground truth of ``root/images/<split>`` with labels from ``root/labels/<split>``.

    ``image_size`` ``(w, h)`` avoids reading every image for its size (all the same size).
    """
    img_dir = Path(root) / "images" / split
    lbl_dir = Path(root) / "labels" / split
    if not img_dir.is_dir():
        raise FileNotFoundError(f"{img_dir}: no such split directory")
    out = []
    for img in sorted(p for p in img_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES):
        size = image_size
        if size is None:
            im = cv2.imread(str(img))
            if im is None:
                raise ValueError(f"{img}: not a readable image")
            size = (im.shape[1], im.shape[0])
        boxes, classes = read_yolo_labels(lbl_dir / f"{img.stem}.txt", size)
        out.append(GroundTruth(img, boxes, classes))
    if not out:
        raise FileNotFoundError(f"{img_dir}: no images")
    return out


def match_image(
    det_boxes: np.ndarray, det_scores: np.ndarray, det_classes: np.ndarray,
    gt_boxes: np.ndarray, gt_classes: np.ndarray, iou_threshold: float = 0.5,
) -> np.ndarray:
    """True-positive flag of each detection (greedy, best score first, one match per gt box)."""
    det_boxes = np.asarray(det_boxes, np.float64).reshape(-1, 4)
    gt_boxes = np.asarray(gt_boxes, np.float64).reshape(-1, 4)
    tp = np.zeros(len(det_boxes), bool)
    used = np.zeros(len(gt_boxes), bool)
    for i in np.argsort(-np.asarray(det_scores, np.float64), kind="stable"):
        cand = np.flatnonzero((~used) & (np.asarray(gt_classes) == det_classes[i]))
        if cand.size == 0:
            continue
        ious = box_iou(det_boxes[i], gt_boxes[cand])
        j = int(np.argmax(ious))
        if ious[j] >= iou_threshold:
            tp[i] = True
            used[cand[j]] = True
    return tp


def average_precision(tp_sorted: np.ndarray, n_gt: int) -> float:
    """All-point interpolated AP from true-positive flags sorted by descending score."""
    if n_gt == 0:
        return float("nan")
    tp_sorted = np.asarray(tp_sorted, bool)
    if tp_sorted.size == 0:
        return 0.0
    ctp = np.cumsum(tp_sorted)
    cfp = np.cumsum(~tp_sorted)
    recall = ctp / n_gt
    precision = ctp / np.maximum(ctp + cfp, 1)
    mrec = np.concatenate([[0.0], recall, [1.0]])
    mpre = np.concatenate([[1.0], precision, [0.0]])
    mpre = np.flip(np.maximum.accumulate(np.flip(mpre)))
    idx = np.flatnonzero(mrec[1:] != mrec[:-1])
    return float(np.sum((mrec[idx + 1] - mrec[idx]) * mpre[idx + 1]))


def evaluate_predictions(
    predictions: Sequence[Sequence[Detection] | tuple[np.ndarray, np.ndarray, np.ndarray]],
    truths: Sequence[GroundTruth | tuple[np.ndarray, np.ndarray]],
    *,
    iou_threshold: float = 0.5,
    score_threshold: float = 0.25,
    class_agnostic: bool = False,
) -> EvalResult:
    """mAP50 / recall / precision of per-image predictions against per-image ground truth.

    ``predictions[i]`` is a list of :class:`Detection` or ``(boxes, scores, classes)`` arrays;
    ``truths[i]`` a :class:`GroundTruth` or ``(boxes, classes)``. With ``class_agnostic`` every
    class id counts as 0 (a detector trained on other class ids still scores).
    """
    if len(predictions) != len(truths):
        raise ValueError(f"{len(predictions)} predictions for {len(truths)} images")
    all_scores, all_tp, all_cls = [], [], []
    gt_count: dict[int, int] = {}
    n_det = 0
    for pred, gt in zip(predictions, truths, strict=True):
        if isinstance(gt, GroundTruth):
            g_boxes, g_cls = gt.boxes, gt.classes
        else:
            g_boxes, g_cls = np.asarray(gt[0], np.float64).reshape(-1, 4), np.asarray(gt[1], np.int64)
        if isinstance(pred, tuple):
            d_boxes, d_scores, d_cls = (np.asarray(a) for a in pred)
        else:
            d_boxes = np.array([d.box for d in pred], np.float64).reshape(-1, 4)
            d_scores = np.array([d.score for d in pred], np.float64)
            d_cls = np.array([d.class_id for d in pred], np.int64)
        d_boxes = np.asarray(d_boxes, np.float64).reshape(-1, 4)
        d_scores = np.asarray(d_scores, np.float64).reshape(-1)
        d_cls = np.asarray(d_cls, np.int64).reshape(-1)
        g_cls = np.asarray(g_cls, np.int64).reshape(-1)
        if class_agnostic:
            d_cls = np.zeros_like(d_cls)
            g_cls = np.zeros_like(g_cls)
        for c in g_cls:
            gt_count[int(c)] = gt_count.get(int(c), 0) + 1
        tp = match_image(d_boxes, d_scores, d_cls, g_boxes, g_cls, iou_threshold)
        all_scores.append(d_scores)
        all_tp.append(tp)
        all_cls.append(d_cls)
        n_det += len(d_scores)
    scores = np.concatenate(all_scores) if all_scores else np.zeros(0)
    tps = np.concatenate(all_tp) if all_tp else np.zeros(0, bool)
    classes = np.concatenate(all_cls) if all_cls else np.zeros(0, np.int64)
    ap: dict[int, float] = {}
    for c, n in sorted(gt_count.items()):
        sel = classes == c
        order = np.argsort(-scores[sel], kind="stable")
        ap[c] = average_precision(tps[sel][order], n)
    n_gt = sum(gt_count.values())
    op = scores >= score_threshold
    tp_op = int(np.sum(tps & op))
    recall = tp_op / n_gt if n_gt else float("nan")
    precision = tp_op / int(np.sum(op)) if np.any(op) else (1.0 if n_gt == 0 else 0.0)
    m = float(np.mean(list(ap.values()))) if ap else float("nan")
    return EvalResult(map50=m, recall=recall, precision=precision, ap50_per_class=ap, n_images=len(truths),
                      n_ground_truth=n_gt, n_detections=n_det, score_threshold=score_threshold)


def evaluate_detector(
    detector: Detector,
    root: str | os.PathLike[str],
    split: str = "test",
    *,
    iou_threshold: float = 0.5,
    score_threshold: float = 0.25,
    class_agnostic: bool = True,
    limit: int | None = None,
    color_order: str | None = None,
) -> EvalResult:
    """Run ``detector`` on every image of a YOLO-format split and score it (see module docstring).

    Images are read with OpenCV (BGR) and converted to the detector's ``config.color_order``
    (``color_order`` overrides it). ``ms_per_frame`` in the result is the median ``detect`` time.
    Single-class by default (``class_agnostic``), the synthetic dataset's setting.
    """
    truths = read_yolo_split(root, split)
    if limit is not None:
        truths = truths[:limit]
    order = color_order or getattr(detector.config, "color_order", "rgb")
    preds: list[list[Detection]] = []
    times: list[float] = []
    for gt in truths:
        img = cv2.imread(str(gt.image), cv2.IMREAD_COLOR)
        if img is None:
            raise ValueError(f"{gt.image}: not a readable image")
        if order == "rgb":
            img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
        t0 = time.perf_counter()
        preds.append(detector.detect(img))
        times.append((time.perf_counter() - t0) * 1e3)
    res = evaluate_predictions(preds, truths, iou_threshold=iou_threshold, score_threshold=score_threshold,
                               class_agnostic=class_agnostic)
    return EvalResult(**{**res.__dict__, "ms_per_frame": float(np.median(times)) if times else None})
