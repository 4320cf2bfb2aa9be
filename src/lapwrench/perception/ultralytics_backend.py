"""ultralytics ``.pt`` weights (optional backend; needs the ``train`` extra).

:mod:`ultralytics` (and torch) are imported only when an :class:`UltralyticsDetector` is built, so
the rest of lapwrench works, and CI passes, without them.
"""

from __future__ import annotations

import importlib
import os
from pathlib import Path
from typing import Any

import numpy as np

from lapwrench.perception.detection import (
    BackendUnavailableError,
    Detection,
    DetectorConfig,
    ModelError,
    finalize,
    validate_frame,
)

INSTALL_HINT = (
    "the ultralytics backend needs the optional 'train' extra: install CPU torch==2.13.0 from local "
    "disk first, then `pip install -e '.[train]'` (or export the model to ONNX and use OnnxYoloDetector)"
)


def _import_ultralytics() -> Any:
    try:
        return importlib.import_module("ultralytics")
    except ImportError as exc:
        raise BackendUnavailableError(f"{INSTALL_HINT} ({exc})") from exc


class UltralyticsDetector:
    """Run ultralytics YOLO weights (``.pt``) on frames, on the CPU.

    Args:
        weights: the ``.pt`` file (trained weights; nothing is downloaded).
        config: thresholds, class filter, NMS mode, frame size, colour order, tracking point.
        imgsz: inference size (largest side) passed to ultralytics.
        device: torch device string.

    Raises:
        BackendUnavailableError: ultralytics is not installed.
        ModelError: the weights file is missing or cannot be loaded.
    """

    def __init__(
        self,
        weights: str | os.PathLike[str],
        config: DetectorConfig | None = None,
        *,
        imgsz: int = 640,
        device: str = "cpu",
    ) -> None:
        self.config = config or DetectorConfig()
        self.weights = Path(weights)
        ultralytics = _import_ultralytics()
        if not self.weights.is_file():
            raise ModelError(self.weights, "weights file not found")
        try:
            self.model = ultralytics.YOLO(str(self.weights), task="detect")
        except Exception as exc:
            raise ModelError(self.weights, f"cannot load ultralytics weights ({type(exc).__name__}: {exc})") from exc
        self.imgsz = int(imgsz)
        self.device = device
        names = getattr(self.model, "names", None)
        self.class_names: dict[int, str] | None = (
            {int(k): str(v) for k, v in names.items()} if isinstance(names, dict) else None
        )

    def detect(self, image: np.ndarray) -> list[Detection]:
        """Instrument detections in one ``H x W x 3`` uint8 frame, best score first.

        Raises:
            FrameError: the frame is empty, not colour, not uint8 or not the configured size.
        """
        image = validate_frame(image, self.config.frame_size)
        # ultralytics treats numpy frames as BGR.
        bgr = image[..., ::-1] if self.config.color_order == "rgb" else image
        cfg = self.config
        results = self.model.predict(
            np.ascontiguousarray(bgr),
            imgsz=self.imgsz,
            conf=cfg.score_threshold,
            iou=cfg.iou_threshold,
            classes=sorted(cfg.classes) if cfg.classes is not None else None,
            agnostic_nms=cfg.agnostic_nms,
            max_det=cfg.max_detections,
            device=self.device,
            verbose=False,
        )
        boxes = results[0].boxes
        xyxy = boxes.xyxy.cpu().numpy() if len(boxes) else np.zeros((0, 4))
        scores = boxes.conf.cpu().numpy() if len(boxes) else np.zeros(0)
        cls = boxes.cls.cpu().numpy().astype(np.int64) if len(boxes) else np.zeros(0, np.int64)
        h, w = image.shape[:2]
        return finalize(xyxy, scores, cls, (w, h), cfg, self.class_names)
