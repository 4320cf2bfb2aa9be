"""The instrument detectors of the simulated runs: the shipped YOLO model, the classical one, a model
file, or the projection of the simulator's known instrument geometry (:class:`ProjectedInstruments`,
reported as such), built by :func:`make_detector` for :class:`~lapwrench.sim.loop.ClosedLoop`.
"""

from __future__ import annotations

import numpy as np

from lapwrench.config import Config
from lapwrench.perception.detection import Detection, Detector, DetectorConfig
from lapwrench.sim.world import SimWorld

DETECTION_SCORE = 0.5  # operating threshold of the detector in the simulated runs


class ProjectedInstruments:
    """Ground-truth stand-in for a detector: the instrument tips projected through the camera.

    A :class:`~lapwrench.perception.detection.Detector` that ignores the image. Used only when
    asked for (``detector="projected"``); the report says so. Tips outside the image or behind the
    camera are not detected.
    """

    name = "projected simulator geometry (no detector)"

    def __init__(self, world: SimWorld, width: int, height: int) -> None:
        self.world = world
        self.width = width
        self.height = height
        self.config = DetectorConfig(frame_size=(width, height))  # the frames it is handed (and ignores)

    def detect(self, image: np.ndarray) -> list[Detection]:
        tips = np.array([self.world.instrument_tip(i) for i in range(self.world.n_instruments)])
        uv, depth = self.world.project_to_image(tips)
        out = []
        for (u, v), z in zip(uv, depth, strict=True):
            if z > 0.005 and 0 <= u < self.width and 0 <= v < self.height:
                box = (max(0.0, u - 12), max(0.0, v - 12), min(self.width, u + 12), min(self.height, v + 12))
                out.append(Detection(box=box, score=1.0, class_id=0, point=(float(u), float(v))))
        return out


def make_detector(spec: str, world: SimWorld, cfg: Config, threads: int | None = None) -> tuple[Detector, str]:
    """The instrument detector of a simulated run and its name for the report.

    ``spec``: ``"shipped"`` (the packaged YOLO ONNX model), ``"classical"``, a path to a ``.onnx``
    or ``.pt`` model, or ``"projected"`` (simulator geometry, no image processing). ``threads``: the
    onnxruntime intra-op threads of an ONNX model (None: the backend's default). One per process when
    every core already runs a scenario (the demo's workers): the same detections, and no threads of one
    run competing with the other runs' cores.
    """
    if spec == "projected":
        projected = ProjectedInstruments(world, cfg.camera.width, cfg.camera.height)
        return projected, projected.name
    from lapwrench import perception

    # One instrument per port: keep that many of the most confident detections above 0.5.
    det_cfg = perception.DetectorConfig(
        frame_size=(cfg.camera.width, cfg.camera.height),
        color_order="rgb",
        score_threshold=DETECTION_SCORE,
        max_detections=world.n_instruments,
    )
    onnx = {} if threads is None else {"num_threads": int(threads)}
    if spec == "shipped":
        options = {**perception.SHIPPED_MODEL_OPTIONS, **onnx}  # shipped_detector's, with these threads
        det = perception.OnnxYoloDetector(perception.SHIPPED_MODEL, det_cfg, **options)
        flip = ", mirrored second pass" if det.test_time_flip else ""
        return det, f"YOLO ONNX detector {perception.SHIPPED_MODEL.name}{flip} on the rendered frames"
    if spec == "classical":
        return perception.make_detector("classical", det_cfg), "classical OpenCV detector on the rendered frames"
    extra = onnx if spec.lower().endswith(".onnx") else {}
    return perception.make_detector(spec, det_cfg, **extra), f"detector {spec} on the rendered frames"
