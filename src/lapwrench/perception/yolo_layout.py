"""The output layouts of YOLO ONNX exports: detecting them and reading candidates out of them.

The output layout of the export is detected when the model loads (:func:`infer_layout`):

========================  ==========================================  ===========================
layout                    outputs                                     exporters
========================  ==========================================  ===========================
``yolov5``                ``[1, N, 5+nc]``: cx, cy, w, h, obj, cls..   YOLOv5; YOLOv7 without NMS
``yolov8``                ``[1, 4+nc, N]``: cx, cy, w, h, cls..        YOLOv8, YOLO11 (ultralytics)
``yolov7_e2e``            ``[N, 7]``: batch, x0, y0, x1, y1, cls, sc   YOLOv7 ``--end2end`` (ORT)
``yolov7_e2e_split``      ``num_dets [1,1]``, ``det_boxes [1,K,4]``,   YOLOv7 ``--end2end``
                          ``det_scores [1,K]``, ``det_classes [1,K]``  TensorRT-style
``e2e_xyxy_score_cls``    ``[1, K, 6]``: x0, y0, x1, y1, score, cls    ultralytics end-to-end
                                                                       (YOLOv10/YOLO26); only from
                                                                       metadata or ``layout=``
========================  ==========================================  ===========================
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lapwrench.perception.boxes import xywh_to_xyxy
from lapwrench.perception.detection import ModelError, PerceptionError

__all__ = ["LayoutInfo", "OutputLayout", "describe_outputs", "forced_layout", "infer_layout", "raw_candidates"]

_SPLIT_NAMES = {
    "num": ("num_dets", "num_detections", "num"),
    "boxes": ("det_boxes", "detection_boxes", "boxes"),
    "scores": ("det_scores", "detection_scores", "scores"),
    "classes": ("det_classes", "detection_classes", "classes", "labels"),
}


class OutputLayout(enum.StrEnum):
    """Output layouts of YOLO ONNX exports (see the module docstring)."""

    YOLOV5 = "yolov5"
    YOLOV8 = "yolov8"
    YOLOV7_E2E = "yolov7_e2e"
    YOLOV7_E2E_SPLIT = "yolov7_e2e_split"
    E2E_XYXY_SCORE_CLS = "e2e_xyxy_score_cls"


@dataclass(frozen=True)
class LayoutInfo:
    """The detected layout and which outputs it reads.

    ``outputs`` holds one output index for single-tensor layouts and four (num, boxes, scores,
    classes) for ``yolov7_e2e_split``. ``num_classes`` is known for raw layouts only.
    """

    layout: OutputLayout
    outputs: tuple[int, ...]
    num_classes: int | None = None


def describe_outputs(outputs: Sequence[tuple[str, Sequence[int]]]) -> str:
    return ", ".join(f"{name} {list(shape)}" for name, shape in outputs)


def infer_layout(
    outputs: Sequence[tuple[str, Sequence[int]]],
    num_classes: int | None = None,
    end2end: bool = False,
) -> LayoutInfo:
    """Work out the YOLO output layout from the outputs' names and (concrete) shapes.

    Args:
        outputs: ``(name, shape)`` of every model output, in order, from an actual run.
        num_classes: the number of classes if known (``nc``); settles ambiguous shapes.
        end2end: the model metadata says it is an ultralytics end-to-end export.

    Raises:
        ValueError: the layout is not one of :class:`OutputLayout` (message lists the outputs).
    """
    names = [name.lower() for name, _ in outputs]
    shapes = [tuple(int(d) for d in shape) for _, shape in outputs]

    # Four-output end-to-end head (TensorRT-style EfficientNMS export), by name then by shape.
    if len(outputs) >= 4:
        idx: dict[str, int] = {}
        for role, role_names in _SPLIT_NAMES.items():
            for i, name in enumerate(names):
                if name in role_names:
                    idx[role] = i
                    break
        if len(idx) < 4 and len(outputs) == 4:
            s = shapes
            if (len(s[0]) == 2 and s[0][1] == 1 and len(s[1]) == 3 and s[1][2] == 4
                    and len(s[2]) == 2 and len(s[3]) == 2):
                idx = {"num": 0, "boxes": 1, "scores": 2, "classes": 3}
        if len(idx) == 4:
            return LayoutInfo(OutputLayout.YOLOV7_E2E_SPLIT,
                              (idx["num"], idx["boxes"], idx["scores"], idx["classes"]))

    # Otherwise one detection tensor: the only output, or the only rank-2/3 one (YOLOv5 exports
    # may carry extra rank-5 per-level grids), or the one called output0/output.
    candidates = [i for i, s in enumerate(shapes) if len(s) in (2, 3)]
    if len(outputs) == 1:
        main = 0
    elif len(candidates) == 1:
        main = candidates[0]
    elif "output0" in names or "output" in names:
        main = names.index("output0") if "output0" in names else names.index("output")
    else:
        raise ValueError(f"cannot tell which output holds the detections: {describe_outputs(outputs)}")
    shape = shapes[main]

    if len(shape) == 2:
        if shape[1] == 7:
            return LayoutInfo(OutputLayout.YOLOV7_E2E, (main,))
        raise ValueError(f"rank-2 output is not [N, 7] (YOLOv7 end-to-end): {describe_outputs(outputs)}")
    if len(shape) != 3 or shape[0] != 1:
        raise ValueError(f"expected a [1, A, B] detection output: {describe_outputs(outputs)}")

    _, a, b = shape
    if end2end:
        if b == 6:
            return LayoutInfo(OutputLayout.E2E_XYXY_SCORE_CLS, (main,))
        raise ValueError(f"end-to-end metadata but output is not [1, K, 6]: {describe_outputs(outputs)}")
    if num_classes is not None:
        v5 = b == 5 + num_classes
        v8 = a == 4 + num_classes
        if v5 and not v8:
            return LayoutInfo(OutputLayout.YOLOV5, (main,), num_classes)
        if v8 and not v5:
            return LayoutInfo(OutputLayout.YOLOV8, (main,), num_classes)
        if not (v5 or v8):
            raise ValueError(
                f"output {list(shape)} matches neither [1, N, 5+nc] nor [1, 4+nc, N] "
                f"for nc={num_classes}: {describe_outputs(outputs)}"
            )
    # Channel axis = the short one: there are far more anchors than channels in practice.
    if a < b and a >= 5:
        return LayoutInfo(OutputLayout.YOLOV8, (main,), a - 4)
    if b < a and b >= 6:
        return LayoutInfo(OutputLayout.YOLOV5, (main,), b - 5)
    raise ValueError(
        f"ambiguous or unknown detection output {list(shape)} (pass num_classes= or layout=): "
        f"{describe_outputs(outputs)}"
    )


def forced_layout(layout: OutputLayout, observed: list[tuple[str, tuple[int, ...]]],
                  num_classes: int | None, model_path: Path) -> LayoutInfo:
    """Check that the observed outputs fit a layout the caller forced (``layout=``), and describe it.

    Raises:
        ModelError: the outputs do not fit ``layout``.
    """
    if layout is OutputLayout.YOLOV7_E2E_SPLIT:
        if len(observed) < 4:
            raise ModelError(model_path, f"layout {layout} needs 4 outputs: {describe_outputs(observed)}")
        return LayoutInfo(layout, (0, 1, 2, 3))
    shape = observed[0][1]
    ok = {
        OutputLayout.YOLOV5: len(shape) == 3 and shape[2] >= 6,
        OutputLayout.YOLOV8: len(shape) == 3 and shape[1] >= 5,
        OutputLayout.YOLOV7_E2E: len(shape) == 2 and shape[1] == 7,
        OutputLayout.E2E_XYXY_SCORE_CLS: len(shape) == 3 and shape[2] == 6,
    }[layout]
    if not ok:
        raise ModelError(model_path, f"output does not fit layout {layout}: {describe_outputs(observed)}")
    nc = {OutputLayout.YOLOV5: shape[-1] - 5, OutputLayout.YOLOV8: shape[1] - 4}.get(layout, num_classes)
    return LayoutInfo(layout, (0,), nc)


def raw_candidates(outputs: Sequence[np.ndarray], info: LayoutInfo, thr: float,
                   model_path: Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Boxes (xyxy input px), scores and classes as the layout ``info`` holds them, unchecked.

    Raw layouts keep only candidates scoring above ``thr``; end-to-end layouts come as they are.

    Raises:
        PerceptionError: a raw output of the wrong rank or too few channels.
    """
    lay = info.layout
    if lay is OutputLayout.YOLOV7_E2E_SPLIT:
        num_o, box_o, score_o, cls_o = (np.asarray(outputs[i]) for i in info.outputs)
        k = min(box_o.size // 4, score_o.size, cls_o.size)
        n = float(num_o.reshape(-1)[0]) if num_o.size else 0.0
        n_i = int(min(max(n, 0.0), k)) if np.isfinite(n) else 0  # a negative count would slice from the end
        return box_o.reshape(-1, 4)[:n_i], score_o.reshape(-1)[:n_i], cls_o.reshape(-1)[:n_i]
    if lay is OutputLayout.YOLOV7_E2E:
        out = np.asarray(outputs[info.outputs[0]], dtype=np.float32).reshape(-1, 7)
        out = out[out[:, 0] == 0]
        return out[:, 1:5], out[:, 6], out[:, 5]
    if lay is OutputLayout.E2E_XYXY_SCORE_CLS:
        out = np.asarray(outputs[info.outputs[0]], dtype=np.float32)[0]
        return out[:, :4], out[:, 4], out[:, 5]
    out = np.asarray(outputs[info.outputs[0]], dtype=np.float32)
    if out.ndim != 3 or out.shape[0] != 1:
        raise PerceptionError(f"{model_path}: unexpected output shape {out.shape} for {lay}")
    if lay is OutputLayout.YOLOV8:
        pred = out[0].T  # [N, 4+nc]
        if pred.shape[1] < 5:
            raise PerceptionError(f"{model_path}: output {out.shape} too narrow for {lay}")
        cls_scores = pred[:, 4:]
    else:  # YOLOV5 / YOLOv7 raw
        pred = out[0]
        if pred.shape[1] < 6:
            raise PerceptionError(f"{model_path}: output {out.shape} too narrow for {lay}")
        pred = pred[pred[:, 4] > thr]  # objectness bounds the final score
        cls_scores = pred[:, 5:] * pred[:, 4:5]
    cls = cls_scores.argmax(axis=1)
    scores = cls_scores[np.arange(len(cls)), cls]
    keep = scores > thr
    pred, cls, scores = pred[keep], cls[keep], scores[keep]
    return xywh_to_xyxy(pred[:, :4]), scores, cls
