"""Shared fixtures: known detections and tiny ONNX graphs emitting them in each YOLO layout."""

from __future__ import annotations

import os

# Headless MuJoCo rendering (dataset and shipped-model tests); must precede any mujoco import.
os.environ.setdefault("MUJOCO_GL", "egl")

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from lapwrench.perception.boxes import letterbox_size
from lapwrench.perception.synthetic import make_constant_yolo_onnx

FRAME_W, FRAME_H = 640, 480
N_ANCHORS = 60
NUM_CLASSES = 3


@dataclass(frozen=True)
class Truth:
    box: tuple[float, float, float, float]  # frame pixels, xyxy
    score: float
    cls: int


# A, a near-duplicate of A (same class), B overlapping A (other class), C, and D below threshold.
TRUTH = {
    "A": Truth((100.0, 100.0, 200.0, 180.0), 0.90, 0),
    "A_dup": Truth((104.0, 102.0, 204.0, 182.0), 0.80, 0),
    "B": Truth((110.0, 105.0, 205.0, 185.0), 0.70, 1),
    "C": Truth((400.0, 300.0, 500.0, 420.0), 0.60, 2),
    "D": Truth((400.0, 50.0, 450.0, 100.0), 0.10, 0),
}


def input_geometry(input_hw: tuple[int, int], dynamic: bool) -> tuple[float, float, float, tuple[int, int]]:
    """ratio, pad_x, pad_y and actual input (h, w) for a 640x480 frame."""
    ratio, (nh, nw), (ih, iw) = letterbox_size((FRAME_H, FRAME_W), input_hw, auto=dynamic)
    return ratio, (iw - nw) / 2.0, (ih - nh) / 2.0, (ih, iw)


def to_input(box: tuple[float, float, float, float], ratio: float, px: float, py: float) -> np.ndarray:
    x0, y0, x1, y1 = box
    return np.array([x0 * ratio + px, y0 * ratio + py, x1 * ratio + px, y1 * ratio + py], np.float32)


def raw_rows(names: list[str], ratio: float, px: float, py: float) -> np.ndarray:
    """Rows ``[cx, cy, w, h, obj, cls...]`` (v5 layout), padded with empty anchors."""
    rows = np.zeros((N_ANCHORS, 5 + NUM_CLASSES), np.float32)
    rows[:, :4] = [10, 10, 4, 4]
    for i, name in enumerate(names):
        t = TRUTH[name]
        x0, y0, x1, y1 = to_input(t.box, ratio, px, py)
        rows[i + 7, :4] = [(x0 + x1) / 2, (y0 + y1) / 2, x1 - x0, y1 - y0]
        rows[i + 7, 4] = t.score
        rows[i + 7, 5 + t.cls] = 1.0
    return rows


def layout_outputs(layout: str, ratio: float, px: float, py: float) -> dict[str, np.ndarray]:
    """The tensors a model of ``layout`` would emit for :data:`TRUTH` (raw layouts include A_dup)."""
    raw_names = ["A", "A_dup", "B", "C", "D"]
    e2e_names = ["A", "B", "C", "D"]
    if layout == "yolov5":
        return {"output": raw_rows(raw_names, ratio, px, py)[None]}
    if layout == "yolov7_raw":
        # YOLOv7 without NMS exports the v5 layout, under another name, with the per-level grids.
        return {
            "output": raw_rows(raw_names, ratio, px, py)[None],
            "onnx::Sigmoid_1": np.zeros((1, 3, 4, 4, 5 + NUM_CLASSES), np.float32),
        }
    if layout == "yolov8":
        rows = raw_rows(raw_names, ratio, px, py)
        v8 = np.concatenate([rows[:, :4], rows[:, 5:] * rows[:, 4:5]], axis=1)  # no objectness
        return {"output0": v8.T[None].copy()}
    if layout == "yolov7_e2e":
        out = np.zeros((len(e2e_names) + 1, 7), np.float32)
        for i, name in enumerate(e2e_names):
            t = TRUTH[name]
            out[i] = [0, *to_input(t.box, ratio, px, py), t.cls, t.score]
        out[-1] = [1, 0, 0, 50, 50, 0, 0.99]  # a detection of batch image 1: ignored
        return {"output": out}
    if layout == "yolov7_e2e_split":
        k = 10
        boxes = np.full((1, k, 4), 5.0, np.float32)
        scores = np.full((1, k), 0.95, np.float32)  # junk beyond num_dets must be ignored
        classes = np.zeros((1, k), np.int32)
        for i, name in enumerate(e2e_names):
            t = TRUTH[name]
            boxes[0, i] = to_input(t.box, ratio, px, py)
            scores[0, i] = t.score
            classes[0, i] = t.cls
        return {
            "num_dets": np.array([[len(e2e_names)]], np.int32),
            "det_boxes": boxes,
            "det_scores": scores,
            "det_classes": classes,
        }
    raise ValueError(layout)


ModelFactory = Callable[..., Path]


@pytest.fixture
def make_layout_model(tmp_path: Path) -> ModelFactory:
    """Factory: ``(layout, input_hw=(640, 640), dynamic=False, metadata=None) -> model path``."""
    pytest.importorskip("onnx", reason="the ONNX layout tests build graphs with the onnx helper API")

    def factory(
        layout: str,
        input_hw: tuple[int, int] = (640, 640),
        dynamic: bool = False,
        metadata: dict[str, str] | None = None,
    ) -> Path:
        ratio, px, py, _ = input_geometry(input_hw, dynamic)
        outputs = layout_outputs(layout, ratio, px, py)
        name = f"{layout}_{input_hw[0]}x{input_hw[1]}_{'dyn' if dynamic else 'static'}.onnx"
        return make_constant_yolo_onnx(tmp_path / name, outputs, input_hw=None if dynamic else input_hw,
                                       metadata=metadata)

    return factory


@pytest.fixture
def frame() -> np.ndarray:
    rng = np.random.default_rng(0)
    return rng.integers(0, 256, (FRAME_H, FRAME_W, 3), dtype=np.uint8)


@pytest.fixture
def truth() -> dict[str, Truth]:
    """The known detections the layout models emit, in frame pixels."""
    return TRUTH
