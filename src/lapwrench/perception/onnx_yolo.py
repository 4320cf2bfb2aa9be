"""YOLO models exported to ONNX, run with onnxruntime on the CPU: :class:`OnnxYoloDetector`.

The model is loaded and checked by :mod:`~lapwrench.perception.yolo_model`; the output layout of the
export (YOLOv5/v7/v8/11 raw heads, YOLOv7 and ultralytics end-to-end heads) is detected when the
model loads (:func:`~lapwrench.perception.yolo_layout.infer_layout`; the table of layouts is in
:mod:`~lapwrench.perception.yolo_layout`). ``OutputLayout``, ``LayoutInfo``, ``infer_layout``,
``DEFAULT_INPUT_SIZE`` and ``MAX_INPUT_SIDE`` are re-exported here.

Boxes are in network-input pixels; they are mapped back through the letterbox to the frame.
Raw layouts go through score threshold, class filter and NMS here; end-to-end layouts already
had NMS in the graph, and get the threshold, class filter and (cheap) NMS again so that the
configuration means the same thing for every layout.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from lapwrench.perception.boxes import Letterbox, fuse_boxes, letterbox, letterbox_size, mirror_boxes, nms
from lapwrench.perception.detection import Detection, DetectorConfig, ModelError, finalize, validate_frame
from lapwrench.perception.yolo_layout import (
    LayoutInfo,
    OutputLayout,
    forced_layout,
    infer_layout,
    raw_candidates,
)
from lapwrench.perception.yolo_model import (
    DEFAULT_INPUT_SIZE,
    MAX_INPUT_SIDE,
    check_floating_outputs,
    open_session,
    parse_names,
    parse_stride,
    read_input,
)

__all__ = [
    "BOX_RANGE",
    "DEFAULT_INPUT_SIZE",
    "MAX_CANDIDATES",
    "MAX_INPUT_SIDE",
    "TTA_FUSION_IOU",
    "LayoutInfo",
    "OnnxYoloDetector",
    "OutputLayout",
    "infer_layout",
]

MAX_CANDIDATES = 3000
"""Raw candidates above the score threshold kept (best first) before NMS."""
BOX_RANGE = 4.0
"""A candidate box reaching beyond this many input sizes from the input is junk and dropped."""
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
        self.test_time_flip = bool(test_time_flip)
        self.config = config or DetectorConfig()
        self.model_path = Path(model_path)
        path = self.model_path
        self.session = open_session(path, num_threads)

        meta = dict(self.session.get_modelmeta().custom_metadata_map or {})
        self.metadata = meta
        meta_names = parse_names(meta)
        if class_names is not None:
            self.class_names: dict[int, str] | None = (
                dict(class_names) if isinstance(class_names, dict) else dict(enumerate(class_names))
            )
        else:
            self.class_names = meta_names
        if num_classes is None and meta_names:
            num_classes = len(meta_names)
        self.stride = parse_stride(meta)

        model_input = read_input(self.session, input_size, meta, path)
        self.input_name = model_input.name
        self.input_dtype = model_input.dtype
        self.input_hw = model_input.hw
        self.dynamic = model_input.dynamic

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
            self.layout = forced_layout(OutputLayout(layout), observed, num_classes, path)
        check_floating_outputs(path, self.layout, self.output_names, outputs)

    # -- setup -------------------------------------------------------------------------------

    def _warmup_frame_hw(self) -> tuple[int, int]:
        if self.config.frame_size is not None:
            w, h = self.config.frame_size
            return (h, w)
        return self.input_hw

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
            boxes, scores, cls = raw_candidates(outputs, self.layout, self.config.score_threshold, self.model_path)
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
