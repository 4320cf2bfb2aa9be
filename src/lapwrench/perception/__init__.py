"""Instrument perception: detectors (ONNX YOLO, ultralytics, classical OpenCV) and camera calibration.

The paper tracks instruments with a YOLOv7 detector (Sec. II-A, IV); each detection's image point
``(u_i, v_i)`` feeds the instrument-tracking wrench (eq 8-12). Every backend implements the
:class:`Detector` protocol: ``detect(image) -> list[Detection]``. Build one with
:func:`make_detector` (``"classical"``, a ``.onnx`` file or a ``.pt`` file).

Also here:

- :mod:`~lapwrench.perception.dataset`: the synthetic YOLO dataset's configuration, labels and files
  (the simulator renders it: :func:`lapwrench.sim.dataset.generate_dataset`, labels from MuJoCo
  segmentation of the instrument jaws);
- :mod:`~lapwrench.perception.evaluate`: mAP50 / recall / precision of any detector on a YOLO split
  (:func:`evaluate_detector`);
- :mod:`~lapwrench.perception.async_detect`: detection at 25 fps with modelled latency for the 1 kHz
  loop (:class:`SimulatedAsyncDetector`, :class:`ThreadedAsyncDetector`);
- :mod:`~lapwrench.perception.train` (training venv only) and :mod:`~lapwrench.perception.cli`
  (``dataset_main``, ``train_main``, ``calibrate_main``).

The shipped model is ``lapwrench/data/models/instruments.onnx`` (:data:`SHIPPED_MODEL`), packaged with the
library; its model card is the ``README.md`` beside it.

The ultralytics backend, the training code and the ONNX test-model builders import their optional
packages lazily. Perception never imports the simulation (the simulation uses the detectors).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from lapwrench.perception.async_detect import SimulatedAsyncDetector, ThreadedAsyncDetector, TimedDetections
from lapwrench.perception.boxes import Letterbox, letterbox, nms
from lapwrench.perception.calibration import (
    CalibrationError,
    CalibrationResult,
    calibrate_from_images,
    read_intrinsics_yaml,
    write_intrinsics_yaml,
)
from lapwrench.perception.classical import ClassicalDetector, ClassicalParams
from lapwrench.perception.dataset import CLASS_NAMES, DatasetConfig
from lapwrench.perception.detection import (
    BackendUnavailableError,
    Detection,
    Detector,
    DetectorConfig,
    FrameError,
    ModelError,
    PerceptionError,
    TrackingPoint,
    TrackingPointRule,
    validate_frame,
)
from lapwrench.perception.evaluate import EvalResult, evaluate_detector, evaluate_predictions
from lapwrench.perception.onnx_yolo import OnnxYoloDetector
from lapwrench.perception.ultralytics_backend import UltralyticsDetector
from lapwrench.perception.yolo_layout import OutputLayout, infer_layout

SHIPPED_MODEL = Path(__file__).resolve().parent.parent / "data" / "models" / "instruments.onnx"
"""The trained model shipped in the repository (exists in a source checkout / editable install)."""

SHIPPED_MODEL_OPTIONS: dict[str, Any] = {"test_time_flip": True}
"""How the shipped model runs (:class:`OnnxYoloDetector` keyword arguments): with its mirrored
second pass, chosen on the validation split (see ``data/models/README.md``)."""


def shipped_detector(config: DetectorConfig | None = None) -> OnnxYoloDetector:
    """The shipped model with its :data:`SHIPPED_MODEL_OPTIONS`.

    Raises:
        ModelError: the model file is missing or cannot be loaded.
    """
    return OnnxYoloDetector(SHIPPED_MODEL, config, **SHIPPED_MODEL_OPTIONS)

__all__ = [
    "CLASS_NAMES",
    "SHIPPED_MODEL",
    "SHIPPED_MODEL_OPTIONS",
    "BackendUnavailableError",
    "CalibrationError",
    "CalibrationResult",
    "ClassicalDetector",
    "ClassicalParams",
    "DatasetConfig",
    "Detection",
    "Detector",
    "DetectorConfig",
    "EvalResult",
    "FrameError",
    "Letterbox",
    "ModelError",
    "OnnxYoloDetector",
    "OutputLayout",
    "PerceptionError",
    "SimulatedAsyncDetector",
    "ThreadedAsyncDetector",
    "TimedDetections",
    "TrackingPoint",
    "TrackingPointRule",
    "UltralyticsDetector",
    "calibrate_from_images",
    "evaluate_detector",
    "evaluate_predictions",
    "infer_layout",
    "letterbox",
    "make_detector",
    "nms",
    "read_intrinsics_yaml",
    "shipped_detector",
    "validate_frame",
    "write_intrinsics_yaml",
]


def make_detector(spec: str | os.PathLike[str], config: DetectorConfig | None = None, **kwargs: Any) -> Detector:
    """Build a detector from a spec: ``"classical"``, a ``.onnx`` model or ``.pt`` ultralytics weights.

    Extra keyword arguments go to the backend's constructor.

    Raises:
        ModelError: the spec is neither ``"classical"`` nor a ``.onnx``/``.pt`` path, or the model
            cannot be loaded.
        BackendUnavailableError: a ``.pt`` file was given and ultralytics is not installed.
    """
    if str(spec) == "classical":
        return ClassicalDetector(config, **kwargs)
    path = Path(spec)
    suffix = path.suffix.lower()
    if suffix == ".onnx":
        return OnnxYoloDetector(path, config, **kwargs)
    if suffix == ".pt":
        return UltralyticsDetector(path, config, **kwargs)
    raise ModelError(path, "unknown detector: expected 'classical', a .onnx model or .pt weights")
