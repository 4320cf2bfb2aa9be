"""YOLO models exported to ONNX, run with onnxruntime on the CPU.

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

Boxes are in network-input pixels; they are mapped back through the letterbox to the frame.
Raw layouts go through score threshold, class filter and NMS here; end-to-end layouts already
had NMS in the graph, and get the threshold, class filter and (cheap) NMS again so that the
configuration means the same thing for every layout.
"""

from __future__ import annotations

import ast
import enum
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from lapwrench.perception.boxes import (
    Letterbox,
    fuse_boxes,
    letterbox,
    letterbox_size,
    mirror_boxes,
    nms,
    xywh_to_xyxy,
)
from lapwrench.perception.detection import (
    Detection,
    DetectorConfig,
    ModelError,
    PerceptionError,
    finalize,
    validate_frame,
)

DEFAULT_INPUT_SIZE = 640
MAX_CANDIDATES = 3000
"""Raw candidates above the score threshold kept (best first) before NMS."""
MAX_INPUT_SIDE = 8192
"""Largest network input side accepted (from the model, its ``imgsz`` metadata or ``input_size``)."""
BOX_RANGE = 4.0
"""A candidate box reaching beyond this many input sizes from the input is junk and dropped."""

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


def _describe(outputs: Sequence[tuple[str, Sequence[int]]]) -> str:
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
        for role, candidates in _SPLIT_NAMES.items():
            for i, name in enumerate(names):
                if name in candidates:
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
        raise ValueError(f"cannot tell which output holds the detections: {_describe(outputs)}")
    shape = shapes[main]

    if len(shape) == 2:
        if shape[1] == 7:
            return LayoutInfo(OutputLayout.YOLOV7_E2E, (main,))
        raise ValueError(f"rank-2 output is not [N, 7] (YOLOv7 end-to-end): {_describe(outputs)}")
    if len(shape) != 3 or shape[0] != 1:
        raise ValueError(f"expected a [1, A, B] detection output: {_describe(outputs)}")

    _, a, b = shape
    if end2end:
        if b == 6:
            return LayoutInfo(OutputLayout.E2E_XYXY_SCORE_CLS, (main,))
        raise ValueError(f"end-to-end metadata but output is not [1, K, 6]: {_describe(outputs)}")
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
                f"for nc={num_classes}: {_describe(outputs)}"
            )
    # Channel axis = the short one: there are far more anchors than channels in practice.
    if a < b and a >= 5:
        return LayoutInfo(OutputLayout.YOLOV8, (main,), a - 4)
    if b < a and b >= 6:
        return LayoutInfo(OutputLayout.YOLOV5, (main,), b - 5)
    raise ValueError(
        f"ambiguous or unknown detection output {list(shape)} (pass num_classes= or layout=): "
        f"{_describe(outputs)}"
    )


def _static_dim(d: Any) -> int | None:
    return int(d) if isinstance(d, int) and d > 0 else None


def _literal(text: str | None) -> object:
    """A metadata value parsed as a Python literal, or None when it is not one (metadata is a hint:
    a model with unreadable metadata still loads, with the defaults)."""
    if not text or len(text) > 100_000:
        return None
    try:
        return ast.literal_eval(text)
    except (ValueError, TypeError, SyntaxError, MemoryError, RecursionError):
        return None


def _parse_names(meta: dict[str, str]) -> dict[int, str] | None:
    """Class names from ultralytics' ``names`` metadata (``{0: 'a', ...}`` or ``['a', ...]``), else None."""
    parsed = _literal(meta.get("names"))
    if isinstance(parsed, dict):
        if not all(type(k) is int for k in parsed):
            return None
        return {k: str(v) for k, v in parsed.items()}
    if isinstance(parsed, list | tuple):
        return {i: str(v) for i, v in enumerate(parsed)}
    return None


def _parse_stride(meta: dict[str, str]) -> int:
    """The model's stride from its metadata: a whole number in [1, 256], else YOLO's usual 32."""
    try:
        stride = float(meta.get("stride", 32))
    except (TypeError, ValueError):
        return 32
    return int(stride) if 1.0 <= stride <= 256.0 else 32


def _valid_size(hw: tuple[object, object]) -> bool:
    """Two whole sizes in [1, MAX_INPUT_SIDE]."""
    return all(type(d) is int and 1 <= d <= MAX_INPUT_SIDE for d in hw)


def _floating_outputs(path: Path, layout: LayoutInfo, names: list[str], outputs: Sequence[object]) -> None:
    """The tensors holding boxes and scores must be floating point (item 8 of issue 11: an integer
    output was accepted silently, and every score was rounded to 0 or 1)."""
    roles = layout.outputs[1:3] if layout.layout is OutputLayout.YOLOV7_E2E_SPLIT else layout.outputs[:1]
    for i in roles:
        dtype = getattr(outputs[i], "dtype", None)
        if dtype is None or np.dtype(dtype).kind != "f":
            kind = np.dtype(dtype).name if dtype is not None else type(outputs[i]).__name__
            raise ModelError(path, f"output '{names[i]}' has dtype {kind}; YOLO boxes and scores must be "
                                   "floating point (float32/float16)")


TTA_FUSION_IOU = 0.55
"""IoU above which a kept box absorbs a candidate in test-time augmentation (weighted box fusion's
usual threshold; on the validation split 0.45/0.55/0.7 scored within 0.004 mAP50 of each other)."""


class OnnxYoloDetector:
    """Run a YOLO ONNX export on frames (onnxruntime, CPU).

    Args:
        model_path: the ``.onnx`` file.
        config: thresholds, class filter, NMS mode, frame size, colour order, tracking point.
        input_size: network input ``(height, width)`` or one int for a square. A model with a fixed
            input size uses its own (a different value here is an error). A model with dynamic
            axes uses this value (default: the model's ``imgsz`` metadata, else 640) as the largest
            side and pads only to a multiple of the stride, so 640x480 frames stay 640x480.
        num_threads: onnxruntime intra-op threads.
        layout: ``"auto"`` (detect) or an :class:`OutputLayout` to force.
        num_classes: number of classes, to settle ambiguous raw output shapes.
        class_names: class names by index (default: the model's ``names`` metadata, if any).
        test_time_flip: also run the horizontally mirrored frame and merge both passes: NMS over
            the candidates of both, then each kept box fused with the candidates overlapping it
            (:func:`~lapwrench.perception.boxes.fuse_boxes`, IoU > :data:`TTA_FUSION_IOU`). About
            twice the inference time.

    Raises:
        ModelError: the file is missing or corrupt, the model does not run, or its input or output
            layout is not a supported YOLO export.
    """

    def __init__(
        self,
        model_path: str | os.PathLike[str],
        config: DetectorConfig | None = None,
        *,
        input_size: int | tuple[int, int] | None = None,
        num_threads: int = 2,
        layout: str | OutputLayout = "auto",
        num_classes: int | None = None,
        class_names: Sequence[str] | dict[int, str] | None = None,
        test_time_flip: bool = False,
    ) -> None:
        import onnxruntime as ort

        self.test_time_flip = bool(test_time_flip)
        self.config = config or DetectorConfig()
        self.model_path = Path(model_path)
        path = self.model_path
        if not path.exists():
            raise ModelError(path, "model file not found")
        if not path.is_file():
            raise ModelError(path, "model path is not a file")
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = max(1, int(num_threads))
        opts.inter_op_num_threads = 1
        opts.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        opts.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        opts.log_severity_level = 3
        try:
            self.session = ort.InferenceSession(str(path), sess_options=opts,
                                                providers=["CPUExecutionProvider"])
        except Exception as exc:
            raise ModelError(path, f"cannot load as an ONNX model ({type(exc).__name__}: {exc})") from exc

        meta = dict(self.session.get_modelmeta().custom_metadata_map or {})
        self.metadata = meta
        meta_names = _parse_names(meta)
        if class_names is not None:
            self.class_names: dict[int, str] | None = (
                dict(class_names) if isinstance(class_names, dict) else dict(enumerate(class_names))
            )
        else:
            self.class_names = meta_names
        if num_classes is None and meta_names:
            num_classes = len(meta_names)
        self.stride = _parse_stride(meta)

        self._setup_input(input_size, meta)

        # One run on a gray frame: checks the model executes and yields the concrete output shapes.
        out_meta = self.session.get_outputs()
        self.output_names = [o.name for o in out_meta]
        warm_hw = self._warmup_frame_hw()
        warm = np.full((*warm_hw, 3), 114, dtype=np.uint8)
        blob, _ = self._preprocess(warm)
        try:
            outputs = self.session.run(None, {self.input_name: blob})
        except Exception as exc:
            raise ModelError(path, f"model failed to run on a {blob.shape} input ({exc})") from exc
        if not all(isinstance(o, np.ndarray) for o in outputs):
            raise ModelError(path, "every output must be a tensor (found a sequence or map output)")
        observed = [(n, o.shape) for n, o in zip(self.output_names, outputs, strict=True)]
        if layout == "auto":
            end2end = str(meta.get("end2end", "")).lower() == "true"
            try:
                self.layout = infer_layout(observed, num_classes=num_classes, end2end=end2end)
            except ValueError as exc:
                raise ModelError(path, f"unknown YOLO output layout: {exc}") from exc
        else:
            self.layout = self._forced_layout(OutputLayout(layout), observed, num_classes)
        _floating_outputs(path, self.layout, self.output_names, outputs)

    # -- setup -------------------------------------------------------------------------------

    def _setup_input(self, input_size: int | tuple[int, int] | None, meta: dict[str, str]) -> None:
        inputs = self.session.get_inputs()
        if len(inputs) != 1:
            raise ModelError(self.model_path, f"expected one image input, found {len(inputs)}: "
                                              f"{[i.name for i in inputs]}")
        inp = inputs[0]
        self.input_name = inp.name
        if inp.type not in ("tensor(float)", "tensor(float16)"):
            raise ModelError(self.model_path, f"input '{inp.name}' has type {inp.type}; expected float/float16")
        self.input_dtype = np.float16 if inp.type == "tensor(float16)" else np.float32
        shape = list(inp.shape)
        if len(shape) != 4 or _static_dim(shape[1]) not in (3, None):
            raise ModelError(self.model_path, f"input '{inp.name}' has shape {shape}; expected [1, 3, H, W]")
        h, w = _static_dim(shape[2]), _static_dim(shape[3])
        wanted: tuple[int, int] | None = None
        if input_size is not None:
            wanted = (input_size, input_size) if isinstance(input_size, int) else tuple(input_size)  # type: ignore[assignment]
            if len(wanted) != 2 or not _valid_size(wanted):  # type: ignore[arg-type]
                raise ModelError(self.model_path, f"configured input_size {str(input_size)[:60]} is not two sizes "
                                                  f"in [1, {MAX_INPUT_SIDE}]")
        if h is not None and w is not None:
            if not _valid_size((h, w)):
                raise ModelError(self.model_path, f"model input of {h}x{w} (HxW) is beyond {MAX_INPUT_SIDE} px")
            if wanted is not None and wanted != (h, w):
                raise ModelError(self.model_path, f"model has a fixed input of {h}x{w} (HxW); "
                                                  f"configured input_size {wanted} differs")
            self.input_hw = (h, w)
            self.dynamic = False
        else:
            if wanted is None:
                wanted = self._meta_imgsz(meta) or (DEFAULT_INPUT_SIZE, DEFAULT_INPUT_SIZE)
            self.input_hw = (int(wanted[0]), int(wanted[1]))
            self.dynamic = True

    @staticmethod
    def _meta_imgsz(meta: dict[str, str]) -> tuple[int, int] | None:
        """The ``imgsz`` metadata as (h, w) if it is one or two sizes in [1, MAX_INPUT_SIDE], else None."""
        val = _literal(meta.get("imgsz"))
        hw = (val, val) if type(val) is int else tuple(val) if isinstance(val, list | tuple) else ()
        return hw if len(hw) == 2 and _valid_size(hw) else None  # type: ignore[return-value]

    def _warmup_frame_hw(self) -> tuple[int, int]:
        if self.config.frame_size is not None:
            w, h = self.config.frame_size
            return (h, w)
        return self.input_hw

    def _forced_layout(self, layout: OutputLayout, observed: list[tuple[str, tuple[int, ...]]],
                       num_classes: int | None) -> LayoutInfo:
        if layout is OutputLayout.YOLOV7_E2E_SPLIT:
            if len(observed) < 4:
                raise ModelError(self.model_path, f"layout {layout} needs 4 outputs: {_describe(observed)}")
            return LayoutInfo(layout, (0, 1, 2, 3))
        shape = observed[0][1]
        ok = {
            OutputLayout.YOLOV5: len(shape) == 3 and shape[2] >= 6,
            OutputLayout.YOLOV8: len(shape) == 3 and shape[1] >= 5,
            OutputLayout.YOLOV7_E2E: len(shape) == 2 and shape[1] == 7,
            OutputLayout.E2E_XYXY_SCORE_CLS: len(shape) == 3 and shape[2] == 6,
        }[layout]
        if not ok:
            raise ModelError(self.model_path, f"output does not fit layout {layout}: {_describe(observed)}")
        nc = {OutputLayout.YOLOV5: shape[-1] - 5, OutputLayout.YOLOV8: shape[1] - 4}.get(layout, num_classes)
        return LayoutInfo(layout, (0,), nc)

    # -- inference ---------------------------------------------------------------------------

    def _preprocess(self, image: np.ndarray) -> tuple[np.ndarray, Letterbox]:
        img, lb = letterbox(np.ascontiguousarray(image), self.input_hw, auto=self.dynamic, stride=self.stride)
        if self.config.color_order == "bgr":
            img = img[..., ::-1]
        blob = np.ascontiguousarray(img.transpose(2, 0, 1)[None], dtype=np.float32)
        blob *= np.float32(1.0 / 255.0)
        if self.input_dtype is not np.float32:
            blob = blob.astype(self.input_dtype)
        return blob, lb

    def input_shape_for(self, frame_hw: tuple[int, int]) -> tuple[int, int]:
        """Network input ``(height, width)`` used for frames of ``frame_hw``."""
        if not self.dynamic:
            return self.input_hw
        return letterbox_size(frame_hw, self.input_hw, auto=True, stride=self.stride)[2]

    def decode(self, outputs: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Raw model outputs -> candidate ``(boxes xyxy input px, scores, class ids)`` above threshold.

        The class filter is applied; NMS is not. Whatever the model emits, a candidate has a finite
        box within :data:`BOX_RANGE` input sizes of the input, a finite class and a score in
        ``(threshold, 1]`` (a score above 1, e.g. an un-squashed logit, counts as 1); any other
        candidate is dropped.
        """
        with np.errstate(invalid="ignore", over="ignore"):
            boxes, scores, cls = self._raw_candidates(outputs)
            boxes = np.asarray(boxes, dtype=np.float32).reshape(-1, 4)
            scores = np.asarray(scores, dtype=np.float32).reshape(-1)
            cls_f = np.asarray(cls, dtype=np.float64).reshape(-1)
            reach = BOX_RANGE * max(self.input_hw)
            # NaN compares False: a non-finite score, box or class drops the candidate here
            keep = (scores > self.config.score_threshold) & (scores < np.inf) & (np.abs(cls_f) < 2**31)
            keep &= (np.abs(boxes) <= reach).all(axis=1)
        cls = cls_f[keep].astype(np.int64)
        if self.config.classes is not None:
            wanted = np.isin(cls, np.fromiter(self.config.classes, dtype=np.int64))
            keep[keep] = wanted
            cls = cls[wanted]
        boxes, scores = boxes[keep], np.minimum(scores[keep], np.float32(1.0))
        if len(scores) > MAX_CANDIDATES:
            top = np.argpartition(-scores, MAX_CANDIDATES)[:MAX_CANDIDATES]
            boxes, scores, cls = boxes[top], scores[top], cls[top]
        return boxes, scores, cls

    def _raw_candidates(self, outputs: Sequence[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Boxes (xyxy input px), scores and classes as the layout holds them, unchecked."""
        thr = self.config.score_threshold
        info = self.layout
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
            raise PerceptionError(f"{self.model_path}: unexpected output shape {out.shape} for {lay}")
        if lay is OutputLayout.YOLOV8:
            pred = out[0].T  # [N, 4+nc]
            if pred.shape[1] < 5:
                raise PerceptionError(f"{self.model_path}: output {out.shape} too narrow for {lay}")
            cls_scores = pred[:, 4:]
        else:  # YOLOV5 / YOLOv7 raw
            pred = out[0]
            if pred.shape[1] < 6:
                raise PerceptionError(f"{self.model_path}: output {out.shape} too narrow for {lay}")
            pred = pred[pred[:, 4] > thr]  # objectness bounds the final score
            cls_scores = pred[:, 5:] * pred[:, 4:5]
        cls = cls_scores.argmax(axis=1)
        scores = cls_scores[np.arange(len(cls)), cls]
        keep = scores > thr
        pred, cls, scores = pred[keep], cls[keep], scores[keep]
        return xywh_to_xyxy(pred[:, :4]), scores, cls

    def detect(self, image: np.ndarray) -> list[Detection]:
        """Instrument detections in one ``H x W x 3`` uint8 frame, best score first.

        Raises:
            FrameError: the frame is empty, not colour, not uint8 or not the configured size.
        """
        image = validate_frame(image, self.config.frame_size)
        blob, lb = self._preprocess(image)
        boxes, scores, cls = self.decode(self.session.run(None, {self.input_name: blob}))
        if self.test_time_flip:
            mirrored = np.ascontiguousarray(blob[..., ::-1])
            m_boxes, m_scores, m_cls = self.decode(self.session.run(None, {self.input_name: mirrored}))
            boxes = np.vstack([boxes, mirror_boxes(m_boxes, blob.shape[-1])])
            scores, cls = np.concatenate([scores, m_scores]), np.concatenate([cls, m_cls])
        per_class = None if self.config.agnostic_nms else cls
        keep = nms(boxes, scores, self.config.iou_threshold, per_class, max_keep=self.config.max_detections)
        kept = fuse_boxes(boxes, scores, keep, TTA_FUSION_IOU, per_class) if self.test_time_flip else boxes[keep]
        frame_boxes = lb.unmap_boxes(kept)
        h, w = image.shape[:2]
        return finalize(frame_boxes, scores[keep], cls[keep], (w, h), self.config, self.class_names)

    def __repr__(self) -> str:
        flip = ", test_time_flip=True" if self.test_time_flip else ""
        return (f"OnnxYoloDetector({str(self.model_path)!r}, layout={self.layout.layout.value}, "
                f"input={self.input_hw}, dynamic={self.dynamic}{flip})")
